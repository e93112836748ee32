"""The state-only demonstrations format: round trip, each error, the dataset and rollout sources."""

from __future__ import annotations

import os
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from rllib_asor.algorithms.common.demonstrations import (
    Demonstrations,
    demonstrations_from_episodes,
    load_demonstrations,
    rollout_demonstrations,
    save_demonstrations,
)

BOX3 = gym.spaces.Box(-np.inf, np.inf, (3,), np.float32)


def two_episodes() -> Demonstrations:
    # episode 0: 3 observations (2 transitions), terminated; episode 1: 2 observations, truncated
    ep0 = np.arange(9, dtype=np.float32).reshape(3, 3)
    ep1 = 100 + np.arange(6, dtype=np.float32).reshape(2, 3)
    return demonstrations_from_episodes([(ep0, True), (ep1, False)])


def test_from_episodes_pairs_consecutive_observations_and_flags_only_the_terminal_step():
    d = two_episodes()
    assert len(d) == 3 and d.num_episodes == 2 and d.obs_shape == (3,)
    np.testing.assert_array_equal(d.obs[1], [3, 4, 5])
    np.testing.assert_array_equal(d.next_obs[1], [6, 7, 8])
    np.testing.assert_array_equal(d.next_obs[2], [103, 104, 105])
    assert d.episode_ids.tolist() == [0, 0, 1]
    assert d.terminateds.tolist() == [False, True, False]
    assert d.obs.dtype == np.float32 and d.episode_ids.dtype == np.int64


def test_npz_round_trip_is_exact_and_leaves_no_temporary_file(tmp_path):
    d = two_episodes()
    path = tmp_path / "sub" / "demos.npz"
    save_demonstrations(path, d)
    assert [p.name for p in path.parent.iterdir()] == ["demos.npz"]
    umask = os.umask(0)
    os.umask(umask)
    assert path.stat().st_mode & 0o777 == 0o666 & ~umask  # not mkstemp's private 0600
    back = load_demonstrations(path, BOX3)
    for name in ("obs", "next_obs", "episode_ids", "terminateds"):
        np.testing.assert_array_equal(getattr(back, name), getattr(d, name))
        assert getattr(back, name).dtype == getattr(d, name).dtype


def test_npz_with_actions_loads_and_ignores_them(tmp_path):
    d = two_episodes()
    np.savez(tmp_path / "d.npz", obs=d.obs, next_obs=d.next_obs, episode_ids=d.episode_ids,
             terminateds=d.terminateds, actions=np.zeros(3))  # fmt: skip
    assert len(load_demonstrations(tmp_path / "d.npz", BOX3)) == 3


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda p: p / "nope.npz", r"nope\.npz do not exist; allowed: an \.npz file"),
        (
            lambda p: (p / "make.py").write_text("#") and p / "nope.npz",
            r"nope\.npz do not exist; write them first: `python .*make\.py`; allowed",
        ),  # a file that the script beside it writes (tuned_examples/paper/demonstrations/)
        (lambda p: (p / "d.csv").write_text("1,2") and p / "d.csv", r"d\.csv: unknown format"),
        (lambda p: p, r"without manifest\.json or parquet files"),
        (
            lambda p: _npz(
                p, obs=np.zeros((0, 3)), next_obs=np.zeros((0, 3)), episode_ids=[], terminateds=[]
            ),
            r"are empty \(0 transitions\)",
        ),  # fmt: skip
        (
            lambda p: _npz(
                p,
                obs=np.zeros((2, 4)),
                next_obs=np.zeros((2, 4)),
                episode_ids=[0, 0],
                terminateds=[0, 1],
            ),
            r"expected \(3,\).*got \(4,\)",
        ),  # fmt: skip
        (lambda p: _npz(p, obs=np.zeros((2, 3))), r"lack the arrays next_obs, episode_ids"),
        (
            lambda p: _npz(
                p,
                obs=np.zeros((2, 3)),
                next_obs=np.zeros((1, 3)),
                episode_ids=[0, 0],
                terminateds=[0, 1],
            ),
            r"next_obs has shape \(1, 3\)",
        ),  # fmt: skip
        (lambda p: (p / "bad.npz").write_bytes(b"not a zip") and p / "bad.npz", "unreadable .npz"),
    ],
    ids=[
        "missing",
        "missing-with-make-script",
        "unknown-format",
        "empty-dir",
        "empty",
        "wrong-shape",
        "missing-arrays",
        "ragged",
        "corrupt",
    ],  # fmt: skip
)
def test_each_bad_input_is_one_value_error_naming_the_path_and_the_problem(tmp_path, make, message):
    path = make(tmp_path)
    with pytest.raises(ValueError, match=message) as e:
        load_demonstrations(path, BOX3)
    assert str(Path(path).name) in str(e.value) and "\n" not in str(e.value)


def _npz(dir: Path, **arrays) -> Path:
    np.savez(dir / "d.npz", **arrays)
    return dir / "d.npz"


def test_collect_dataset_task_dir_gives_its_expert_level_and_a_part_dir_that_part(
    hopper_offline_data,
):
    from rllib_asor.algorithms.maple.data import read_part
    from rllib_asor.data.format import read_manifest

    space = gym.make("rllib_asor/HopperShift-v0").observation_space
    manifest = read_manifest(hopper_offline_data)
    d = load_demonstrations(hopper_offline_data, space)
    expert_steps = sum(
        manifest["datasets"][dyn]["expert"]["num_steps"] for dyn in manifest["datasets"]
    )
    assert len(d) == expert_steps and d.obs_shape == space.shape
    part = hopper_offline_data / "original" / "random"
    one = load_demonstrations(part, space)
    episodes = read_part(part)
    assert len(one) == sum(len(acts) for _, acts, _, _ in episodes)
    np.testing.assert_array_equal(one.obs[0], episodes[0][0][0])
    np.testing.assert_array_equal(one.next_obs[0], episodes[0][0][1])
    assert one.num_episodes == len(episodes)
    assert one.terminateds.sum() == sum(t for *_, t in episodes)
    with pytest.raises(ValueError, match=r"expected \(3,\), got \(11,\)"):
        load_demonstrations(part, BOX3)


def test_rollout_of_a_scripted_lava_expert_reaches_the_goal_in_its_demonstrations(tmp_path):
    from rllib_asor.envs.lava import GOAL, LavaWorldEnv

    env = LavaWorldEnv(lava_row=3, obs_mode="raw")

    def down_right_down(obs):  # (row, col, flag): (0,4) -> (2,4) -> (2,6) -> (5,6), safe for k=3
        row, col, _ = obs
        return 2 if row < 2 or col == 6 else 1

    d = rollout_demonstrations(down_right_down, env, episodes=2, seed=0)
    assert d.num_episodes == 2 and d.terminateds.sum() == 2
    last = d.next_obs[d.terminateds]
    assert (last[:, :2] == np.array(GOAL, dtype=np.float32)).all()
    save_demonstrations(tmp_path / "lava.npz", d)
    assert len(load_demonstrations(tmp_path / "lava.npz", env.observation_space)) == len(d)


def test_rollout_refuses_zero_episodes():
    with pytest.raises(ValueError, match="episodes=0 is invalid"):
        rollout_demonstrations(lambda o: 0, "rllib_asor/LavaWorld-v0", episodes=0)
