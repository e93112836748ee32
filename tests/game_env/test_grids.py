"""Observation grids: one batched gather gives each racer its own windows, centred on it."""

from __future__ import annotations

import numpy as np
import pytest

from game_env import generate_course
from game_env.grids import CourseGrids


@pytest.fixture(scope="module")
def course():
    return generate_course(2, 0)


def test_a_batch_of_racers_gets_the_grids_each_would_get_alone(course):
    batch, single = CourseGrids(course, 3), CourseGrids(course, 1)
    x = np.array([-50.0, 3.3, course.length + 80.0])  # before, on and far past the course
    y = np.array([0.0, 1.3, -40.0])
    feet = np.array([0.0, 0.5, -3.0])
    got = batch.observe(x, y, feet)
    for i in range(3):
        want = single.observe(x[i : i + 1], y[i : i + 1], feet[i : i + 1])
        for g, w in zip(got, want, strict=True):
            np.testing.assert_array_equal(g[i], w[0])
    terrain = got[0]
    assert terrain.shape == (3, 4, 16, 16) and terrain.dtype == np.float32
    assert (terrain[2, 0] == -1.0).all()  # no floor anywhere near: heights clipped to -1


def test_the_centre_cell_holds_the_highest_floor_of_the_metre_under_the_racer(course):
    grids = CourseGrids(course, 1)
    x, y, feet = 3.3, 0.6, 0.5
    terrain = grids.observe(np.array([x]), np.array([y]), np.array([feet]))[0]
    i, j = int((x - grids.x_min) / 1.0), int((y - grids.y_min) / 1.0)  # res-1 cell: 4 x 4 fine cells
    top = grids.fine_h[4 * i : 4 * i + 4, 4 * j : 4 * j + 4].max()
    assert terrain[0, 0, 8, 8] == pytest.approx(np.clip(0.2 * (top - feet), -1, 1), abs=1e-6)
