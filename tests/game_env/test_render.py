"""rgb_array rendering through MuJoCo's offscreen renderer (EGL) and the preview CLI."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np

import game_env

ROOT = Path(__file__).parents[2]


def test_rgb_array_frames_have_the_requested_size_and_show_something():
    env = gym.make("game_env/ObstacleRace-v0", map_id=4, render_mode="rgb_array", width=160, height=120)
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (120, 160, 3) and frame.dtype == np.uint8
    assert frame.std() > 5
    env.close()
    penv = game_env.parallel_env(num_racers=2, render_mode="rgb_array", width=96, height=64)
    penv.reset(seed=0)
    assert penv.render().shape == (64, 96, 3)
    penv.close()


def test_preview_cli_writes_a_png(tmp_path):
    out = tmp_path / "map3.png"
    subprocess.run([sys.executable, "-m", "game_env.preview", "--map", "3", "--out", str(out)],
                   check=True, cwd=ROOT, capture_output=True)
    assert out.stat().st_size > 10_000


def test_preview_cli_rejects_unknown_map():
    res = subprocess.run([sys.executable, "-m", "game_env.preview", "--map", "12", "--out", "x.png"],
                         cwd=ROOT, capture_output=True, text=True)
    assert res.returncode != 0 and "map_id=12" in res.stderr
