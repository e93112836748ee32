"""`import game_env` never needs a GL library; the backend is chosen at the first render.

A machine without libEGL is simulated in a subprocess: a prelude makes `ctypes.CDLL` refuse
every library whose name holds "EGL" (what the dynamic loader does when libEGL is absent).
The first test shows the simulation bites: plain `import mujoco` with `MUJOCO_GL=egl` then
fails with PyOpenGL's error, as on the GPU node where this was found.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from game_env.gl import GLUnavailableError, choose_backend, library_loads

ROOT = Path(__file__).parents[2]

NO_EGL = """
import ctypes
_load = ctypes.CDLL.__init__
def _refuse_egl(self, name, *args, **kwargs):
    if name and "EGL" in str(name):
        raise OSError(f"{name}: cannot open shared object file: No such file or directory")
    return _load(self, name, *args, **kwargs)
ctypes.CDLL.__init__ = _refuse_egl
"""
NO_OSMESA = NO_EGL.replace('"EGL" in str(name)', '("EGL" in str(name) or "OSMesa" in str(name))')

STEP_A_RACE = """
import gymnasium as gym
import game_env
env = gym.make("game_env/ObstacleRace-v0", map_id=1, render_mode="rgb_array", width=64, height=48)
env.reset(seed=0)
for _ in range(5):
    env.step(env.action_space.sample())
print("stepped")
"""


def _python(code: str, **env: str | None) -> subprocess.CompletedProcess[str]:
    environ = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "PYOPENGL_PLATFORM")}
    for key, value in env.items():
        if value is None:
            environ.pop(key, None)
        else:
            environ[key] = value
    return subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, env=environ, capture_output=True, text=True,
        timeout=120,
    )


def test_the_simulated_machine_has_no_egl_and_plain_mujoco_import_fails_there() -> None:
    res = _python(NO_EGL + "import mujoco", MUJOCO_GL="egl")
    assert res.returncode != 0
    assert "eglQueryString" in res.stderr or "EGL" in res.stderr


@pytest.mark.parametrize("mujoco_gl", ["egl", "osmesa", None])
def test_import_game_env_and_stepping_need_no_gl(mujoco_gl: str | None) -> None:
    res = _python(NO_OSMESA + STEP_A_RACE + "import os; print(os.environ.get('MUJOCO_GL'))",
                  MUJOCO_GL=mujoco_gl)
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.split() == ["stepped", str(mujoco_gl)]  # MUJOCO_GL left as it was


def test_the_mujoco_shift_envs_import_without_egl() -> None:
    code = NO_EGL + (
        "import gymnasium as gym, rllib_asor\n"
        "env = gym.make('rllib_asor/HopperShift-v0'); env.reset(seed=0)\n"
        "env.step(env.action_space.sample()); print('stepped')\n"
    )
    res = _python(code, MUJOCO_GL="egl")
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.strip() == "stepped"


def test_render_without_any_gl_says_in_one_line_what_to_install() -> None:
    code = NO_OSMESA + STEP_A_RACE + (
        "from game_env.gl import GLUnavailableError\n"
        "try:\n    env.render()\nexcept GLUnavailableError as e:\n    print('ERROR', e)\n"
    )
    res = _python(code, MUJOCO_GL="egl")
    assert res.returncode == 0, res.stderr[-2000:]
    lines = res.stdout.strip().splitlines()
    assert lines[0] == "stepped" and len(lines) == 2
    assert lines[1].startswith("ERROR no OpenGL library for MuJoCo's renderer")
    assert "egl: libEGL not found" in lines[1] and "osmesa: libOSMesa not found" in lines[1]
    assert "libegl1" in lines[1] and "libosmesa6" in lines[1]


@pytest.mark.skipif(not library_loads("egl"), reason="this machine has no libEGL to render with")
def test_without_a_display_or_a_choice_the_first_render_uses_egl() -> None:
    code = STEP_A_RACE + (
        "frame = env.render()\n"
        "import game_env.gl as gl\n"
        "print(frame.shape, frame.std() > 5, gl.gl_context_class().__module__)\n"
    )
    res = _python(code, MUJOCO_GL=None)
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.strip().splitlines()[-1] == "(48, 64, 3) True mujoco.egl"


def test_backend_choice_follows_the_request_then_falls_back() -> None:
    if library_loads("egl"):
        assert choose_backend({"MUJOCO_GL": "egl"}) == "egl"
        assert choose_backend({}) == "egl"  # no display: not glfw
        assert choose_backend({"MUJOCO_GL": "osmesa"}) == ("osmesa" if library_loads("osmesa") else "egl")
    with pytest.raises(GLUnavailableError, match=r"MUJOCO_GL='vulkan' is invalid: allowed egl \| osmesa \| glfw"):
        choose_backend({"MUJOCO_GL": "vulkan"})
    with pytest.raises(GLUnavailableError, match="switches rendering off"):
        choose_backend({"MUJOCO_GL": "disable"})


def test_pyopengl_platform_is_the_only_candidate_when_set() -> None:
    """PyOpenGL binds one platform per process: falling back past it cannot work."""
    if library_loads("osmesa"):
        pytest.skip("this machine has OSMesa")
    with pytest.raises(GLUnavailableError, match=r"\(osmesa: libOSMesa not found\)"):
        choose_backend({"MUJOCO_GL": "egl", "PYOPENGL_PLATFORM": "osmesa"})
