"""MuJoCo's OpenGL backend, chosen when a frame is first rendered, never at import.

MuJoCo reads ``MUJOCO_GL`` when ``mujoco`` is imported and loads that backend's GL library
then: with ``MUJOCO_GL=egl`` and no libEGL, PyOpenGL's EGL binding fails inside
``import mujoco`` and takes the whole import with it. `import_mujoco` imports MuJoCo with its GL
backend switched off (``MUJOCO_GL=disable`` for the import only; the variable is restored), so
simulating, and training, needs no GL library at all. `gl_context_class`, called before the
first render, picks the backend: ``MUJOCO_GL`` when it names one, else glfw when there is a
display; then EGL, then OSMesa; the first whose library loads. With none, one line says what
to install (`GLUnavailableError`).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import importlib
import os
import sys
from collections.abc import Mapping
from types import ModuleType
from typing import Any

BACKENDS = ("egl", "osmesa", "glfw")
"""MuJoCo's Linux backends this module can choose (``glx`` is MuJoCo's glfw)."""
_OFF = ("disable", "disabled", "off", "false", "0")
_AUTO = ("", "enable", "enabled", "on", "true", "1")
_LIBRARIES = {"egl": ("EGL", "libEGL.so.1"), "osmesa": ("OSMesa", "libOSMesa.so.8"),
              "glfw": ("GL", "libGL.so.1")}
INSTALL_HINT = (
    "install EGL (apt-get install libegl1; an NVIDIA driver brings its own) or OSMesa "
    "(apt-get install libosmesa6), or set MUJOCO_GL to a backend this machine has; "
    "simulation and training need no GL"
)

_chosen: type | None = None


class GLUnavailableError(RuntimeError):
    """No OpenGL backend for MuJoCo's renderer on this machine (the message is one line)."""


def import_mujoco() -> ModuleType:
    """``mujoco``, imported without loading any GL library (see the module docstring)."""
    if "mujoco" in sys.modules:
        return sys.modules["mujoco"]
    saved = os.environ.get("MUJOCO_GL")
    os.environ["MUJOCO_GL"] = "disable"
    try:
        import mujoco
    finally:
        if saved is None:
            os.environ.pop("MUJOCO_GL", None)
        else:
            os.environ["MUJOCO_GL"] = saved
    _install(_FirstUseGLContext, replace_real=False)
    return mujoco


class _FirstUseGLContext:
    """Stands in for ``mujoco.GLContext`` until a renderer first asks for a context; then the
    backend is chosen (`gl_context_class`) and its context returned."""

    def __new__(cls, max_width: int, max_height: int) -> Any:
        return gl_context_class()(max_width, max_height)


def _gl_context_modules() -> list[ModuleType]:
    names = ("mujoco.rendering.classic.gl_context", "mujoco.gl_context", "mujoco")
    return [sys.modules[n] for n in names if n in sys.modules]


def _install(cls: type, *, replace_real: bool) -> None:
    """Make `cls` the ``GLContext`` that ``mujoco.Renderer`` builds (it looks the name up on
    its ``gl_context`` module at construction)."""
    for module in _gl_context_modules():
        current = getattr(module, "GLContext", None)
        if replace_real or current is None or _is_placeholder(current):
            module.GLContext = cls


def _is_placeholder(cls: Any) -> bool:
    """Ours, or MuJoCo's own stand-in for a backend that failed to import."""
    return cls is _FirstUseGLContext or getattr(cls, "__name__", "") == "_MissingGLContext"


def gl_context_class() -> type:
    """MuJoCo's ``GLContext`` class of the backend chosen for this process (chosen once)."""
    global _chosen
    if _chosen is not None:
        return _chosen
    import_mujoco()
    existing = [getattr(m, "GLContext", None) for m in _gl_context_modules()]
    real = [c for c in existing if c is not None and not _is_placeholder(c)]
    if real:  # MuJoCo was imported elsewhere with a working backend: keep it
        _chosen = real[0]
        return _chosen
    backend = choose_backend(os.environ)
    try:
        module = importlib.import_module(f"mujoco.{backend}")
        cls = module.GLContext
    except (ImportError, AttributeError, OSError) as err:
        first = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise GLUnavailableError(
            f"MuJoCo's {backend} rendering backend failed to load ({first}); {INSTALL_HINT}"
        ) from err
    _install(cls, replace_real=True)
    _chosen = cls
    return cls


def choose_backend(environ: Mapping[str, str]) -> str:
    """The backend to render with: the first of the candidates whose library loads.

    Candidates: ``MUJOCO_GL`` first when it names a backend (``glx`` counts as glfw), else
    glfw when ``DISPLAY`` is set; then egl, then osmesa. ``PYOPENGL_PLATFORM``, when set to egl
    or osmesa, is the only candidate (PyOpenGL binds that platform for the whole process).
    """
    requested = environ.get("MUJOCO_GL", "").strip().lower()
    if requested == "glx":
        requested = "glfw"
    if requested in _OFF:
        raise GLUnavailableError(
            f"MUJOCO_GL={environ.get('MUJOCO_GL')!r} switches rendering off; unset it or set "
            f"one of {' | '.join(BACKENDS)} to render"
        )
    if requested not in _AUTO and requested not in BACKENDS:
        raise GLUnavailableError(
            f"MUJOCO_GL={environ.get('MUJOCO_GL')!r} is invalid: allowed {' | '.join(BACKENDS)} "
            "(or unset: chosen at the first render)"
        )
    first = [requested] if requested in BACKENDS else (["glfw"] if environ.get("DISPLAY") else [])
    candidates = list(dict.fromkeys([*first, "egl", "osmesa"]))
    platform = environ.get("PYOPENGL_PLATFORM", "").strip().lower()
    if platform in ("egl", "osmesa"):
        candidates = [platform]
    tried = []
    for backend in candidates:
        if library_loads(backend):
            return backend
        tried.append(f"{backend}: lib{_LIBRARIES[backend][0]} not found")
    raise GLUnavailableError(
        f"no OpenGL library for MuJoCo's renderer ({'; '.join(tried)}): {INSTALL_HINT}"
    )


def library_loads(backend: str) -> bool:
    """Whether the GL library that `backend` needs can be loaded into this process."""
    name, soname = _LIBRARIES[backend]
    for candidate in dict.fromkeys(filter(None, [ctypes.util.find_library(name), soname])):
        try:
            ctypes.CDLL(candidate)
        except OSError:
            continue
        return True
    return False
