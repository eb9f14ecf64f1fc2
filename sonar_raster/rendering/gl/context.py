"""Headless OpenGL contexts: EGL (default) or OSMesa, chosen in one place.

The backend is the explicit argument, else the ``SONAR_RASTER_GL`` environment variable
("egl" or "osmesa"), else EGL with OSMesa as the fallback. This module is the only place that
reads that variable.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
from typing import Any

from ...errors import SonarRasterError

BACKENDS = ("egl", "osmesa")
ENV_VAR = "SONAR_RASTER_GL"
GL_REQUIRE = 430  # compute shaders and storage buffers

_MISSING_PACKAGES = (
    "no headless OpenGL could start; install Mesa's EGL and OSMesa, e.g. on Debian/Ubuntu "
    "'sudo apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri libosmesa6' "
    "(or render on the CPU with --renderer reference)"
)

# OSMesa constants (osmesa.h).
_OSMESA_FORMAT, _OSMESA_RGBA = 0x22, 0x1908
_OSMESA_DEPTH_BITS, _OSMESA_PROFILE, _OSMESA_CORE_PROFILE = 0x30, 0x33, 0x34
_OSMESA_MAJOR, _OSMESA_MINOR = 0x36, 0x37
_GL_UNSIGNED_BYTE = 0x1401


def requested_backends(backend: str | None = None) -> tuple[str, ...]:
    """Backends to try, in order, from the argument or the environment.

    Raises
    ------
    SonarRasterError
        If the backend name is not "egl" or "osmesa".
    """
    choice = backend or os.environ.get(ENV_VAR) or None
    if choice is None:
        return BACKENDS
    choice = choice.strip().lower()
    if choice not in BACKENDS:
        raise SonarRasterError(f"unknown GL backend {choice!r}; use one of: {', '.join(BACKENDS)}")
    return (choice,)


class _OSMesaLoader:
    """A moderngl loader that owns one current OSMesa core-profile context."""

    def __init__(self) -> None:
        name = ctypes.util.find_library("OSMesa") or "libOSMesa.so.8"
        try:
            lib = ctypes.CDLL(name)
        except OSError as exc:
            raise RuntimeError(f"libOSMesa not found ({exc})") from None
        lib.OSMesaCreateContextAttribs.restype = ctypes.c_void_p
        lib.OSMesaCreateContextAttribs.argtypes = [ctypes.POINTER(ctypes.c_int), ctypes.c_void_p]
        lib.OSMesaMakeCurrent.argtypes = [
            ctypes.c_void_p,
            ctypes.c_void_p,
            ctypes.c_uint,
            ctypes.c_int,
            ctypes.c_int,
        ]
        lib.OSMesaGetProcAddress.restype = ctypes.c_void_p
        lib.OSMesaGetProcAddress.argtypes = [ctypes.c_char_p]
        lib.OSMesaDestroyContext.argtypes = [ctypes.c_void_p]
        attrs = [
            _OSMESA_FORMAT,
            _OSMESA_RGBA,
            _OSMESA_DEPTH_BITS,
            24,
            _OSMESA_PROFILE,
            _OSMESA_CORE_PROFILE,
            _OSMESA_MAJOR,
            4,
            _OSMESA_MINOR,
            5,
            0,
        ]
        handle = lib.OSMesaCreateContextAttribs((ctypes.c_int * len(attrs))(*attrs), None)
        if not handle:
            raise RuntimeError("OSMesaCreateContextAttribs failed (no OpenGL 4.5 core profile)")
        self._buffer = (ctypes.c_ubyte * 16)()  # a 2x2 RGBA default framebuffer, never drawn to
        if not lib.OSMesaMakeCurrent(handle, self._buffer, _GL_UNSIGNED_BYTE, 2, 2):
            lib.OSMesaDestroyContext(handle)
            raise RuntimeError("OSMesaMakeCurrent failed")
        self._lib, self._handle = lib, handle

    def __enter__(self) -> None:
        """Make this context current (moderngl calls it from ``with ctx:``)."""
        self._lib.OSMesaMakeCurrent(self._handle, self._buffer, _GL_UNSIGNED_BYTE, 2, 2)

    def __exit__(self, *exc: object) -> None:
        return None

    def load_opengl_function(self, name: str) -> int:
        return self._lib.OSMesaGetProcAddress(name.encode()) or 0

    def release(self) -> None:
        if self._handle:
            self._lib.OSMesaDestroyContext(self._handle)
            self._handle = None


def _create(backend: str) -> Any:
    import moderngl

    if backend == "egl":
        return moderngl.create_standalone_context(backend="egl", require=GL_REQUIRE)  # type: ignore[arg-type]
    loader = _OSMesaLoader()
    ctx = moderngl.create_context(require=GL_REQUIRE, context=loader)  # type: ignore[arg-type]
    ctx.extra = {"osmesa_loader": loader}
    return ctx


def create_context(backend: str | None = None) -> tuple[Any, str]:
    """Create a headless moderngl context.

    Parameters
    ----------
    backend : {"egl", "osmesa"} or None
        Force one backend; None reads ``SONAR_RASTER_GL`` and otherwise tries EGL, then OSMesa.

    Returns
    -------
    ctx : moderngl.Context
        A context with OpenGL >= 4.3 (compute shaders).
    name : str
        The backend that started.

    Raises
    ------
    SonarRasterError
        If no requested backend starts; the message names the system packages to install.
    """
    tried = []
    for name in requested_backends(backend):
        try:
            return _create(name), name
        except (RuntimeError, ValueError, OSError, ImportError) as exc:
            tried.append(f"{name}: {str(exc).splitlines()[0] if str(exc) else type(exc).__name__}")
    raise SonarRasterError(f"{_MISSING_PACKAGES} [{'; '.join(tried)}]")


def release_context(ctx: Any) -> None:
    """Release a context made by :func:`create_context` (safe to call twice)."""
    if ctx is None:
        return
    ctx.release()
    loader = (ctx.extra or {}).get("osmesa_loader") if isinstance(ctx.extra, dict) else None
    if loader is not None:
        loader.release()
        ctx.extra = None


def probe(backend: str) -> dict[str, str]:
    """Try one backend and describe it (for ``sonar-raster doctor``)."""
    try:
        ctx, _ = create_context(backend)
    except SonarRasterError as exc:
        return {"backend": backend, "ok": "no", "error": str(exc)}
    try:
        return {
            "backend": backend,
            "ok": "yes",
            "renderer": ctx.info["GL_RENDERER"],
            "version": ctx.info["GL_VERSION"],
            "max_texture_size": str(ctx.info["GL_MAX_TEXTURE_SIZE"]),
        }
    finally:
        release_context(ctx)
