"""The coherent model's fast path: visibility from the GL range maps agrees with one ray per
scatterer, per-surface spacing, and the estimate that sizes a job before it starts."""

import numpy as np
import pytest

from sonar_raster._progress import Estimate, check_job, duration_text
from sonar_raster.errors import SonarRasterError
from sonar_raster.rendering.coherent.model import face_spacing, render_coherent
from sonar_raster.rendering.coherent.scatter import scatter_surface
from sonar_raster.sonar import Sonar
from sonar_raster.trajectory import Trajectory

pytestmark = pytest.mark.usefixtures("strict_float")

SONAR = Sonar(frequency_hz=20e3, max_range=12.0, range_bin=0.1, sides=("port", "starboard"))


@pytest.fixture(scope="module")
def track():
    return Trajectory.straight((0.0, 0.6, 4.0), 0.0, 0.2, 6)


def test_range_map_visibility_agrees_with_one_ray_per_scatterer(shadow_scene, track):
    kw = {"spacing_wavelengths": 0.5, "seabed_spacing_wavelengths": 0.5, "seed": 2}
    depth = render_coherent(shadow_scene, SONAR, track, visibility="depth", **kw)
    rays = render_coherent(shadow_scene, SONAR, track, visibility="rays", **kw)
    md, mr = depth.metadata, rays.metadata
    assert md["n_scatterers"] == mr["n_scatterers"] > 20_000
    hidden = md["n_scatterers"] - mr["n_visible"]
    assert hidden > 0.05 * md["n_scatterers"]  # the shadows hide a good share
    # the two tests disagree only at shadow edges (one ray of the map wide: a few percent)
    assert abs(md["n_visible"] - mr["n_visible"]) < 0.1 * hidden
    for side in ("port", "starboard"):
        a, b = depth.sides[side].astype(float), rays.sides[side].astype(float)
        assert np.abs(a - b).sum() < 0.01 * b.sum()


def test_seabed_faces_get_the_seabed_spacing(shadow_scene):
    spacing = face_spacing(shadow_scene, 0.01, 0.04)
    is_seabed = shadow_scene.object_id == shadow_scene.names.index("seabed")
    assert np.all(spacing[is_seabed] == 0.04) and np.all(spacing[~is_seabed] == 0.01)
    surface = scatter_surface(shadow_scene, np.zeros(3), spacing)
    _, area = shadow_scene.face_normals_areas()
    facets = surface.n_sub.astype(float) ** 2
    # about one scatterer per spacing² on the seabed's compact triangles; objects' facets are
    # no larger than their own spacing² (thin triangles get more, smaller facets)
    assert facets[is_seabed].sum() == pytest.approx(area[is_seabed].sum() / 0.04**2, rel=0.1)
    assert surface.facet_area[~is_seabed].max() <= 0.01**2


def test_estimate_counts_the_scatterers_it_will_generate(shadow_scene, track):
    image = render_coherent(shadow_scene, SONAR, track, spacing_wavelengths=1.0)
    est = image.metadata["estimate"]["counts"]["scatterers"]
    assert est == pytest.approx(image.metadata["n_scatterers"], rel=0.5)


def test_a_job_over_an_hour_is_refused_in_one_line_before_any_work(shadow_scene, track):
    # estimated ~12 days: far enough over the hour that a faster engine still refuses it (at
    # 5e-4 the compiled engine's estimate fell to 0.5 h and the test ran the job)
    with pytest.raises(SonarRasterError) as err:
        render_coherent(
            shadow_scene, SONAR, track, spacing_wavelengths=2e-5, seabed_spacing_wavelengths=2e-5
        )
    message = str(err.value)
    assert "\n" not in message
    assert "--scatterer-spacing" in message and "--force" in message
    assert "over the 60 min limit" in message and "days" in message


def test_check_job_limits_time_and_memory_unless_forced():
    quick = Estimate("job", {"rays": 10}, seconds=5.0, memory=1e3)
    check_job(quick, "lower --x")
    for slow in (
        Estimate("job", {"rays": 10}, seconds=2e4),
        Estimate("job", {"rays": 10}, seconds=1.0, memory=1e20),
    ):
        with pytest.raises(SonarRasterError, match="lower --x"):
            check_job(slow, "lower --x")
        check_job(slow, "lower --x", force=True)


@pytest.mark.parametrize(
    ("seconds", "text"), [(4.24, "4.2 s"), (45, "45 s"), (600, "10 min"), (7200, "2.0 h")]
)
def test_duration_text(seconds, text):
    assert duration_text(seconds) == text


def test_reference_job_over_an_hour_is_refused_and_its_estimate_counts_patches(shadow_scene, track):
    from sonar_raster.rendering.reference import render_reference

    with pytest.raises(SonarRasterError, match="--range-bin") as err:
        render_reference(shadow_scene, SONAR, track, patch_size=1e-4)
    assert "\n" not in str(err.value)
    image = render_reference(shadow_scene, SONAR, track)
    est = image.metadata["estimate"]["counts"]["patches"]
    assert est == pytest.approx(image.metadata["n_patches"], rel=0.5)
