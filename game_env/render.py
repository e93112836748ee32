"""Offscreen rendering with MuJoCo's renderer; the GL backend (egl, osmesa, glfw) is chosen
at the first renderer (`game_env.gl`)."""

from __future__ import annotations

import mujoco
import numpy as np

from game_env.gl import gl_context_class


class RaceRenderer:
    """Renders a chase view of one racer, or an overview of the whole course."""

    def __init__(self, model: mujoco.MjModel, width: int = 320, height: int = 240) -> None:
        gl_context_class()  # the backend, or GLUnavailableError saying what to install
        self.renderer = mujoco.Renderer(model, height=height, width=width)
        for flag in (mujoco.mjtRndFlag.mjRND_SHADOW, mujoco.mjtRndFlag.mjRND_REFLECTION):
            self.renderer.scene.flags[flag] = False
        self.camera = mujoco.MjvCamera()
        self.camera.type = mujoco.mjtCamera.mjCAMERA_FREE

    def chase(self, data: mujoco.MjData, target: np.ndarray) -> np.ndarray:
        """Frame from behind and above ``target`` (x, y, z), looking along +x."""
        cam = self.camera
        cam.lookat[:] = [target[0] + 3.0, target[1], target[2]]
        cam.distance, cam.azimuth, cam.elevation = 11.0, 0.0, -22.0
        return self._draw(data)

    def overview(self, data: mujoco.MjData, x0: float, x1: float, z: float) -> np.ndarray:
        """Frame of the course between ``x0`` and ``x1`` from the side and above."""
        cam = self.camera
        cam.lookat[:] = [(x0 + x1) / 2, 0.0, z]
        cam.distance, cam.azimuth, cam.elevation = 0.7 * (x1 - x0) + 8.0, 70.0, -24.0
        return self._draw(data)

    def _draw(self, data: mujoco.MjData) -> np.ndarray:
        self.renderer.update_scene(data, self.camera)
        for flag in (mujoco.mjtRndFlag.mjRND_SHADOW, mujoco.mjtRndFlag.mjRND_REFLECTION):
            self.renderer.scene.flags[flag] = False
        return self.renderer.render()

    def close(self) -> None:
        self.renderer.close()
