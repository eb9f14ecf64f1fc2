"""The package's shape: the public API resolves, stages import only what they should."""

from __future__ import annotations

import ast
import importlib
import inspect
import subprocess
import sys
from pathlib import Path

import pytest

import sonar_raster

PACKAGE = Path(sonar_raster.__file__).parent
SUBPACKAGES = (
    "scenes",
    "meshio",
    "rendering",
    "rendering.gl",
    "rendering.coherent",
    "effects",
    "io",
    "inversion",
    "dataset",
)


def _modules() -> list[Path]:
    return sorted(PACKAGE.rglob("*.py"))


def _imports(path: Path) -> set[str]:
    """Absolute names of the modules ``path`` imports (relative imports resolved)."""
    rel = path.relative_to(PACKAGE.parent).with_suffix("")
    package = list(rel.parts[:-1]) if rel.name != "__init__" else list(rel.parts[:-1])
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = package[: len(package) - node.level + 1] if node.level else []
            name = ".".join(base + ([node.module] if node.module else []))
            out.add(name)
            out.update(f"{name}.{alias.name}" for alias in node.names)
    return out


def test_every_public_name_resolves():
    for name in sonar_raster.__all__:
        assert getattr(sonar_raster, name) is not None, name
    for sub in SUBPACKAGES:
        module = importlib.import_module(f"sonar_raster.{sub}")
        for name in module.__all__:
            assert getattr(module, name) is not None, f"{sub}.{name}"


def test_render_and_invert_stay_functions_after_their_subpackages_load():
    import sonar_raster.inversion.solver  # noqa: F401
    import sonar_raster.rendering.gl.raster  # noqa: F401
    from sonar_raster import invert, render

    assert inspect.isfunction(render) and inspect.isfunction(invert)


def test_public_callables_document_their_parameters():
    """Every public function and class has a docstring; functions taking arguments list them."""
    for name in sonar_raster.__all__:
        obj = getattr(sonar_raster, name)
        doc = inspect.getdoc(obj)
        assert doc, f"{name} has no docstring"
        if inspect.isfunction(obj) and inspect.signature(obj).parameters:
            assert "Parameters\n---" in doc, f"{name}: no Parameters section"


def test_only_rendering_gl_knows_opengl():
    owners = {p for p in _modules() if _imports(p) & {"moderngl", "glcontext"}}
    outside = [str(p.relative_to(PACKAGE)) for p in owners if "rendering/gl" not in p.as_posix()]
    assert not outside, f"modules outside rendering/gl import moderngl: {outside}"


def test_the_library_never_imports_the_cli():
    bad = []
    for path in _modules():
        rel = path.relative_to(PACKAGE).as_posix()
        if rel.startswith("cli/") or rel == "__main__.py":
            continue
        if any(
            name == "sonar_raster.cli" or name.startswith("sonar_raster.cli.")
            for name in _imports(path)
        ):
            bad.append(rel)
    assert not bad, f"library modules import the CLI: {bad}"


def test_no_module_imports_another_modules_private_names():
    """``from x import _name`` across modules would make private names a hidden API."""
    bad = []
    for path in _modules():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.module and node.level:
                private = [a.name for a in node.names if a.name.startswith("_")]
                if private and not node.module.startswith("_"):
                    bad.append(f"{path.relative_to(PACKAGE)}: {node.module} {private}")
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize(
    "folder", ["scenes", "meshio", "rendering", "effects", "io", "inversion", "dataset", "cli"]
)
def test_each_stage_is_a_folder(folder):
    assert (PACKAGE / folder / "__init__.py").is_file()


def test_importing_the_package_loads_no_heavy_module():
    code = (
        "import sys, sonar_raster\n"
        "heavy = [m for m in ('moderngl', 'trimesh', 'scipy', 'OpenImageIO', 'pyxtf')"
        " if m in sys.modules]\n"
        "print(heavy)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
