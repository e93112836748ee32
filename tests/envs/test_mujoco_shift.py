"""MuJoCo dynamics shift: real physics changes, modes, presets, check_env."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import rllib_asor.envs  # noqa: F401  (registers the ids)
from rllib_asor.envs.mujoco_shift import MujocoShiftEnv, parse_dynamics

# Gymnasium's v5 MuJoCo envs declare an unbounded Box; check_env warns about it (not ours).
pytestmark = pytest.mark.filterwarnings("ignore:.*Box observation space:UserWarning")

IDS = {
    "rllib_asor/HalfCheetahShift-v0": "HalfCheetah-v5",
    "rllib_asor/Walker2dShift-v0": "Walker2d-v5",
    "rllib_asor/HopperShift-v0": "Hopper-v5",
    "rllib_asor/AntShift-v0": "Ant-v5",
}


def _rollout(env: MujocoShiftEnv, seed: int, steps: int, options: dict | None = None):
    """qpos after `steps` steps of a fixed (seeded) action sequence; env infos."""
    env.reset(seed=seed, options=options)
    actions = np.random.default_rng(123).uniform(-1, 1, (steps, *env.action_space.shape))
    infos = []
    for a in actions:
        *_, info = env.step(a.astype(np.float32))
        infos.append(info)
    return env.env.unwrapped.data.qpos.copy(), infos


@pytest.mark.parametrize("env_id", sorted(IDS))
def test_check_env_passes_and_id_wraps_v5_model(env_id: str) -> None:
    env = gym.make(env_id, params=("mass", "damping", "friction", "gravity", "inertia", "wind"))
    inner = env.unwrapped
    assert isinstance(inner, MujocoShiftEnv) and inner.base_id == IDS[env_id]
    check_env(inner, skip_render_check=True)
    _, info = env.reset(seed=0)
    assert set(info["dynamics"]) == {"mass", "damping", "friction", "gravity", "inertia", "wind"}
    env.close()


def test_sampled_values_follow_escp_ranges_and_are_written_to_the_model() -> None:
    env = MujocoShiftEnv(
        "HalfCheetah-v5", params=("mass", "damping", "friction", "gravity", "wind")
    )
    lo, hi = 1.5**-3, 1.5**3
    masses = []
    for seed in range(20):
        _, info = env.reset(seed=seed)
        d = info["dynamics"]
        for name in ("mass", "damping", "friction", "gravity"):
            assert lo <= d[name] <= hi
        assert np.all(np.abs(d["wind"]) <= 3.0)
        m, nom = env.model, env.nominal
        np.testing.assert_allclose(m.body_mass, nom["body_mass"] * d["mass"])
        np.testing.assert_allclose(m.dof_damping, nom["dof_damping"] * d["damping"])
        np.testing.assert_allclose(m.geom_friction, nom["geom_friction"] * d["friction"])
        np.testing.assert_allclose(m.opt.gravity, nom["gravity"] * d["gravity"])
        np.testing.assert_allclose(m.opt.wind[:2], d["wind"])
        assert m.opt.density == pytest.approx(1.2)
        masses.append(d["mass"])
    assert len(set(masses)) == 20  # a fresh draw every episode


def test_per_element_multipliers_scale_each_body() -> None:
    env = MujocoShiftEnv("Hopper-v5", params=("mass",), per_element=True)
    _, info = env.reset(seed=3)
    mult = info["dynamics"]["mass"]
    assert mult.shape == env.nominal["body_mass"].shape and len(set(mult.round(6))) > 1
    np.testing.assert_allclose(env.model.body_mass, env.nominal["body_mass"] * mult)


def test_mass_x3_changes_the_trajectory_of_the_same_actions() -> None:
    env = MujocoShiftEnv("HalfCheetah-v5", dynamics="original")
    q_nominal, infos = _rollout(env, seed=0, steps=40)
    assert infos[-1]["dynamics_id"] == 0
    q_heavy, infos = _rollout(env, seed=0, steps=40, options={"dynamics": "mass_x3"})
    np.testing.assert_allclose(env.model.body_mass, env.nominal["body_mass"] * 3.0)
    assert infos[-1]["dynamics"] == {"mass": 3.0}
    assert np.abs(q_heavy - q_nominal).max() > 1e-2
    # the next reset without options returns to this env's own (nominal) setting
    env.reset(seed=0)
    np.testing.assert_allclose(env.model.body_mass, env.nominal["body_mass"])


def test_wind_with_air_density_pushes_the_body_downwind() -> None:
    x = {}
    for wx in (-3.0, 3.0):
        env = MujocoShiftEnv("Hopper-v5", fixed={"wind": (wx, 0.0)})
        assert env.reset(seed=0)[1]["dynamics"]["wind"].tolist() == [wx, 0.0]
        assert env.model.opt.density == pytest.approx(1.2)
        env.reset(seed=0)
        for _ in range(50):
            env.step(np.zeros(env.action_space.shape, np.float32))
        x[wx] = env.env.unwrapped.data.qpos[0]
    assert x[3.0] - x[-3.0] > 1e-3


def test_offline_presets_original_body_mass_density_10() -> None:
    assert parse_dynamics("original") == {}
    assert parse_dynamics("body_mass") == {"mass": 3.0}
    assert parse_dynamics("mass_x3") == {"mass": 3.0}
    assert parse_dynamics("damping_x0.5") == {"damping": 0.5}
    env = MujocoShiftEnv("Walker2d-v5", dynamics="density_10")
    env.reset(seed=0)
    assert env.model.opt.density == 10.0 and np.all(env.model.opt.wind == 0)
    np.testing.assert_allclose(env.model.body_mass, env.nominal["body_mass"])
    q_dense, _ = _rollout(env, 0, 30)
    q_orig, _ = _rollout(MujocoShiftEnv("Walker2d-v5", dynamics="original"), 0, 30)
    assert np.abs(q_dense - q_orig).max() > 1e-4


def test_fixed_mode_is_deterministic_across_seeds_and_runs() -> None:
    env = MujocoShiftEnv("Hopper-v5", fixed={"mass": 3.0})
    ids = {env.reset(seed=s)[1]["dynamics_id"] for s in range(5)}
    assert len(ids) == 1 and ids != {0}
    q1, _ = _rollout(env, 7, 30)
    q2, _ = _rollout(MujocoShiftEnv("Hopper-v5", dynamics="mass_x3"), 7, 30)
    np.testing.assert_array_equal(q1, q2)


def test_non_stationary_switch_happens_after_step_k() -> None:
    k = 5
    env = MujocoShiftEnv("HalfCheetah-v5", params=("mass", "damping"), switch_every=k)
    env.reset(seed=0)
    seen = []
    for _ in range(3 * k):
        *_, info = env.step(np.zeros(6, np.float32))
        seen.append((info["dynamics"]["mass"], info["dynamics_id"]))
        np.testing.assert_allclose(env.model.body_mass, env.nominal["body_mass"] * seen[-1][0])
    first, second, third = seen[:k], seen[k : 2 * k], seen[2 * k :]
    assert len(set(first)) == len(set(second)) == len(set(third)) == 1
    assert first[0] != second[0] != third[0]


def test_task_pool_with_switching_picks_pool_tasks_mid_episode() -> None:
    env = MujocoShiftEnv("Hopper-v5", num_tasks=4, switch_every=2)
    env.reset(seed=0)
    pool = {i: t["mass"] for i, t in enumerate(env.tasks)}
    for _ in range(12):
        *_, term, trunc, info = env.step(np.zeros(3, np.float32))
        assert pool[info["dynamics_id"]] == info["dynamics"]["mass"]
        if term or trunc:
            break


def test_task_pool_gives_small_ids_and_repeats_dynamics() -> None:
    env = MujocoShiftEnv("HalfCheetah-v5", num_tasks=3, task_seed=1)
    seen = {}
    for s in range(20):
        _, info = env.reset(seed=s)
        seen.setdefault(info["dynamics_id"], info["dynamics"]["mass"])
        assert seen[info["dynamics_id"]] == info["dynamics"]["mass"]
    assert set(seen) == {0, 1, 2}
    other = MujocoShiftEnv("HalfCheetah-v5", num_tasks=3, task_seed=1)
    assert [t["mass"] for t in other.tasks] == [t["mass"] for t in env.tasks]


@pytest.mark.parametrize(
    ("kwargs", "key"),
    [
        ({"base_id": "Humanoid-v5"}, "base_id"),
        ({"params": ("mass", "colour")}, "params"),
        ({"params": ("density",)}, "params"),
        ({"fixed": {"mass": -1.0}}, "fixed"),
        ({"fixed": {"wind": (1, 2, 3)}}, "wind"),
        ({"fixed": {"density": "thick"}}, "density"),
        ({"fixed": {"mass": "heavy"}}, "mass"),
        ({"dynamics": "mass_times_3"}, "dynamics"),
        ({"switch_every": 0}, "switch_every"),
        ({"num_tasks": 0}, "num_tasks"),
        ({"log_scale_limit": -1}, "log_scale_limit"),
    ],
)
def test_bad_options_raise_value_error_naming_key(kwargs: dict, key: str) -> None:
    with pytest.raises(ValueError, match=key):
        MujocoShiftEnv(**kwargs)
