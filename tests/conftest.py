"""Shared fixtures: one GL renderer per backend for the session, checked for GL errors.

Tests of real data (XTF recordings, VRML model files) read ``../shared/data`` beside the clone.
Where it is missing they skip, and the run's header says so; with
``SONAR_RASTER_REQUIRE_SHARED=1`` (set by ``.ci/run``) a missing folder stops the run instead,
so CI never passes without testing real data.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from sonar_raster.scene import MeshPart, build_scene

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = ROOT.parent / "shared" / "data"
REQUIRE_SHARED = "SONAR_RASTER_REQUIRE_SHARED"


def pytest_report_header(config):
    if SHARED_DATA.is_dir():
        return f"real data: {SHARED_DATA}"
    return f"real data: {SHARED_DATA} is missing; the XTF and model-file tests will skip"


def pytest_sessionstart(session):
    if os.environ.get(REQUIRE_SHARED) == "1" and not SHARED_DATA.is_dir():
        pytest.exit(
            f"{REQUIRE_SHARED}=1 but {SHARED_DATA} is missing: clone beside the shared folder",
            returncode=1,
        )


def _renderer(backend: str):
    from sonar_raster.rendering.gl.raster import RasterRenderer

    return RasterRenderer(backend)


@pytest.fixture(scope="session")
def gl_renderer():
    """An EGL renderer (the default backend) shared by the session."""
    renderer = _renderer("egl")
    yield renderer
    renderer.release()


@pytest.fixture(scope="session")
def osmesa_renderer():
    renderer = _renderer("osmesa")
    yield renderer
    renderer.release()


@pytest.fixture()
def gl(gl_renderer):
    """The session renderer, asserting no GL error before and after the test."""
    with gl_renderer.ctx:
        assert gl_renderer.ctx.error == "GL_NO_ERROR"
    yield gl_renderer
    with gl_renderer.ctx:
        assert gl_renderer.ctx.error == "GL_NO_ERROR"


def plane(size: float, z: float = 0.0, reflectivity: float = 0.5, center=(0.0, 0.0)) -> MeshPart:
    """A square seabed of two triangles, counter-clockwise from above."""
    cx, cy = center
    h = size / 2
    v = np.array(
        [[cx - h, cy - h, z], [cx + h, cy - h, z], [cx + h, cy + h, z], [cx - h, cy + h, z]]
    )
    return MeshPart(v, np.array([[0, 1, 2], [0, 2, 3]]), reflectivity, "seabed", is_seabed=True)


def box(center, size, reflectivity: float = 0.9, name: str = "box") -> MeshPart:
    """An axis-aligned closed box with outward faces."""
    import trimesh

    mesh = trimesh.creation.box(extents=size)
    return MeshPart(
        np.asarray(mesh.vertices) + np.asarray(center), np.asarray(mesh.faces), reflectivity, name
    )


@pytest.fixture()
def flat_scene():
    return build_scene([plane(200.0)])


@pytest.fixture()
def strict_float():
    """Raise on any floating-point overflow, division by zero or invalid operation."""
    with np.errstate(all="raise"):
        yield


def rect_seabed(x0, x1, y0, y1, z=0.0, reflectivity=0.5) -> MeshPart:
    """Axis-aligned flat rectangle of two triangles, normal +z."""
    v = np.array([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]], dtype=float)
    return MeshPart(v, np.array([[0, 1, 2], [0, 2, 3]]), reflectivity, "seabed", True)


def box_from_bounds(bounds, reflectivity=0.8, name="box") -> MeshPart:
    """A closed box with outward faces spanning ``bounds`` = [[min xyz], [max xyz]]."""
    import trimesh

    mesh = trimesh.creation.box(bounds=np.asarray(bounds, dtype=float))
    return MeshPart(np.array(mesh.vertices), np.array(mesh.faces), reflectivity, name)


@pytest.fixture(scope="session")
def shadow_scene():
    """A seabed with a box on each side of a track along +y at x 0, each casting a shadow."""
    return build_scene(
        [
            rect_seabed(-1, 13, -8, 8),
            box_from_bounds([[5.0, 2.0, 0.0], [5.8, 3.5, 0.7]]),
            box_from_bounds([[-0.5, -5.0, 0.0], [3.0, -4.2, 0.4]], name="ledge"),
        ]
    )
