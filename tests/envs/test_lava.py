"""Lava world: layout facts (value iteration / exhaustive search), API, check_env."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import rllib_asor.envs  # noqa: F401  (registers the ids)
from rllib_asor.envs.lava import (
    FIXED_LAVA,
    GOAL,
    LAVA_ROWS,
    LavaWorldEnv,
    best_reactive_policy,
    best_reactive_returns,
    lava_cells,
    optimal_return,
    optimal_routes,
    reactive_expert,
)

UP, RIGHT, DOWN, LEFT = 0, 1, 2, 3
# the only 7-step route under lava row 3: down, down, right, right, down, down, down
ROUTE_ROW3 = [DOWN, DOWN, RIGHT, RIGHT, DOWN, DOWN, DOWN]


@pytest.mark.parametrize("obs_mode", ["onehot", "raw"])
def test_check_env_passes(obs_mode: str) -> None:
    check_env(LavaWorldEnv(obs_mode=obs_mode), skip_render_check=True)


def test_registered_id_makes_env_with_kwargs() -> None:
    env = gym.make("rllib_asor/LavaWorld-v0", lava_row=4, obs_mode="raw")
    obs, info = env.reset(seed=0)
    assert obs.shape == (3,) and info["dynamics_id"] == 4
    env.close()


def test_optimal_return_per_lava_row_by_value_iteration() -> None:
    assert {k: optimal_return(k) for k in LAVA_ROWS} == {2: 0.82, 3: 0.86, 4: 0.86, 5: 0.86}
    assert {k: optimal_return(k, layout="E") for k in LAVA_ROWS} == dict.fromkeys(LAVA_ROWS, 0.84)
    assert LavaWorldEnv.optimal_return(2) == 0.82  # also reachable from the class


def test_optimal_route_changes_with_lava_row() -> None:
    routes = {k: {tuple(r) for r in optimal_routes(k)} for k in LAVA_ROWS}
    # no route is optimal under every lava row
    assert not set.intersection(*routes.values())
    # row 3 has one optimal route, and it crosses the cells that are lava in row 2
    (only,) = routes[3]
    assert (2, 4) in only and (2, 5) in only
    # under row 2 every optimal route detours through column 3
    assert all((2, 3) in r and (2, 4) not in r for r in routes[2])
    # and every route avoids the lava of its own row
    for k, rs in routes.items():
        assert all(not set(r) & lava_cells(k) and r[-1] == GOAL for r in rs)


def test_best_observation_only_policy_is_082_on_every_row() -> None:
    # exhaustive search over memoryless policies on (row, col, flag): the flag cannot reveal
    # row 2 before (2,3), so the best reactive policy takes the 9-step detour everywhere.
    assert best_reactive_returns("B") == dict.fromkeys(LAVA_ROWS, 0.82)
    assert best_reactive_returns("B", lava_rows=(3, 4, 5)) == dict.fromkeys((3, 4, 5), 0.86)


def test_best_reactive_policy_achieves_its_returns_in_the_env() -> None:
    policy = best_reactive_policy("B")
    env = LavaWorldEnv(obs_mode="raw")
    for k in LAVA_ROWS:
        obs, _ = env.reset(seed=0, options={"lava_row": k})
        total, done = 0.0, False
        while not done:
            key = (int(obs[0]), int(obs[1]), bool(obs[2]))
            obs, r, term, trunc, info = env.step(policy[key])
            total, done = total + r, term or trunc
        assert info["is_success"] and total == pytest.approx(0.82)


@pytest.mark.parametrize("obs_mode", ["onehot", "raw"])
def test_the_reactive_expert_acts_on_the_envs_observations_and_scores_082(obs_mode: str) -> None:
    act = reactive_expert(obs_mode=obs_mode)
    env = LavaWorldEnv(obs_mode=obs_mode)
    for k in LAVA_ROWS:
        obs, _ = env.reset(seed=0, options={"lava_row": k})
        total, done = 0.0, False
        while not done:
            obs, r, term, trunc, info = env.step(act(obs))
            total, done = total + r, term or trunc
        assert info["is_success"] and total == pytest.approx(0.82)


def test_the_reactive_expert_refuses_an_unknown_obs_mode() -> None:
    with pytest.raises(ValueError, match=r"obs_mode='pixels' is not allowed; expected one of"):
        reactive_expert(obs_mode="pixels")


def test_no_random_reactive_policy_beats_the_exhaustive_search() -> None:
    rng = np.random.default_rng(0)
    env = LavaWorldEnv(obs_mode="raw")
    best = sum(best_reactive_returns("B").values())
    for _ in range(100):
        table = rng.integers(0, 4, size=(7, 7, 2))
        # bias towards the goal (down/right) so some policies do reach it
        table = np.where(rng.random((7, 7, 2)) < 0.7, rng.choice([1, 2], size=(7, 7, 2)), table)
        total = 0.0
        for k in LAVA_ROWS:
            obs, _ = env.reset(seed=0, options={"lava_row": k})
            done = False
            while not done:
                obs, r, term, trunc, _ = env.step(int(table[int(obs[0]), int(obs[1]), int(obs[2])]))
                total, done = total + r, term or trunc
        assert total <= best + 1e-9


def _run(env: LavaWorldEnv, actions: list[int], lava_row: int):
    env.reset(seed=0, options={"lava_row": lava_row})
    total, out = 0.0, None
    for a in actions:
        out = env.step(a)
        total += out[1]
        assert out[1] == pytest.approx(out[4]["reward_step"] + out[4]["reward_goal"])
        if out[2] or out[3]:
            break
    return total, out


def test_row3_route_reaches_goal_under_row3_but_dies_under_row2() -> None:
    env = LavaWorldEnv()
    total, (_, _, term, trunc, info) = _run(env, ROUTE_ROW3, 3)
    assert term and not trunc and info["is_success"] and total == pytest.approx(0.86)
    total, (_, _, term, _, info) = _run(env, ROUTE_ROW3, 2)
    assert term and info["in_lava"] and not info["is_success"] and total == pytest.approx(-0.04)


def test_fixed_lava_on_row1_kills() -> None:
    total, (_, _, term, _, info) = _run(LavaWorldEnv(), [RIGHT, DOWN], 5)
    assert term and info["in_lava"] and (info["row"], info["col"]) == FIXED_LAVA[0]


def test_episode_truncates_at_50_steps() -> None:
    env = LavaWorldEnv()
    env.reset(seed=0, options={"lava_row": 3})
    for t in range(1, 51):
        _, r, term, trunc, info = env.step(UP)  # into the border: stays in place
        assert not term and trunc == (t == 50) and r == pytest.approx(-0.02)
    assert info["steps"] == 50


def test_lava_row_drawn_from_all_rows_and_fixed_option() -> None:
    env = LavaWorldEnv()
    seen = {env.reset(seed=s)[1]["dynamics_id"] for s in range(40)}
    assert seen == set(LAVA_ROWS)
    env = LavaWorldEnv(lava_row=3)
    assert {env.reset(seed=s)[1]["dynamics_id"] for s in range(10)} == {3}
    env = LavaWorldEnv(lava_rows=(4, 5))
    assert {env.reset(seed=s)[1]["lava_row"] for s in range(20)} == {4, 5}


def test_observation_modes_and_flag() -> None:
    env = LavaWorldEnv(obs_mode="onehot")
    obs, _ = env.reset(seed=0, options={"lava_row": 2})
    assert obs.shape == (15,) and obs[0] == 1 and obs[7 + 4] == 1 and obs[-1] == 0
    # (1,4) always touches fixed lava (1,5): flag 1 under every row
    assert all(env.observation_at(1, 4, k)[-1] == 1 for k in LAVA_ROWS)
    # (2,3) touches (2,4) only when the lava is on row 2
    assert [LavaWorldEnv(obs_mode="raw").observation_at(2, 3, k)[2] for k in LAVA_ROWS] == [
        1,
        0,
        0,
        0,
    ]
    np.testing.assert_array_equal(LavaWorldEnv(obs_mode="raw").observation_at(3, 6, 5), [3, 6, 0])


def test_cells_lists_free_cells() -> None:
    cells = LavaWorldEnv.cells()
    assert len(cells) == 49 - 2 and (1, 5) not in cells and (3, 4) in cells
    assert len(LavaWorldEnv.cells(3)) == 45 and (3, 4) not in LavaWorldEnv.cells(3)


def test_observation_grid_stacks_observations_of_free_cells() -> None:
    env = LavaWorldEnv(obs_mode="raw")
    cells, obs = env.observation_grid(2)
    assert len(cells) == 45 and obs.shape == (45, 3)
    np.testing.assert_array_equal(obs[cells.index((2, 3))], [2, 3, 1])
    assert LavaWorldEnv().observation_grid(5)[1].shape == (45, 15)


def test_render_ansi_shows_agent_lava_goal() -> None:
    env = LavaWorldEnv(render_mode="ansi")
    env.reset(seed=0, options={"lava_row": 3})
    text = env.render()
    assert text.count("A") == 1 and text.count("L") == 4 and text.count("G") == 1


@pytest.mark.parametrize(
    ("kwargs", "key"),
    [
        ({"lava_row": 1}, "lava_row"),
        ({"lava_row": "3"}, "lava_row"),
        ({"lava_rows": (2, 7)}, "lava_rows"),
        ({"lava_rows": ()}, "lava_rows"),
        ({"obs_mode": "pixels"}, "obs_mode"),
        ({"layout": "Z"}, "layout"),
        ({"max_steps": 0}, "max_steps"),
        ({"render_mode": "human"}, "render_mode"),
    ],
)
def test_bad_options_raise_value_error_naming_key(kwargs: dict, key: str) -> None:
    with pytest.raises(ValueError, match=key):
        LavaWorldEnv(**kwargs)


def test_bad_reset_option_and_action_raise() -> None:
    env = LavaWorldEnv()
    with pytest.raises(ValueError, match="lava_row"):
        env.reset(options={"lava_row": 6})
    with pytest.raises(ValueError, match="options"):
        env.reset(options={"wind": 1})
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action"):
        env.step(4)
    with pytest.raises(ValueError, match="row"):
        env.observation_at(7, 0, 2)
