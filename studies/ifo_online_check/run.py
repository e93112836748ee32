"""GAIfO on the lava world and GARAT on a grounded Pendulum (README.md beside this file).

    python studies/ifo_online_check/run.py gaifo    # then: ... run.py garat
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

import rllib_asor  # noqa: F401  (registers our env ids)
from rllib_asor.algorithms.common.demonstrations import (
    rollout_demonstrations,
    save_demonstrations,
)
from rllib_asor.envs.lava import reactive_expert
from rllib_asor.evaluation.rollout import module_policy, stack_obs
from studies.lib.lava_imitation import LAVA, lava_score, save_result

HERE = Path(__file__).parent
RESULTS = HERE / "results.json"
SEEDS = (0, 1)


# ----------------------------------------------------------------------------- GAIfO


def gaifo(reward_form: str = "gail") -> None:
    from rllib_asor.algorithms.gaifo.config import GaifoConfig

    tag = "gaifo" if reward_form == "gail" else f"gaifo_{reward_form}"

    demos = rollout_demonstrations(reactive_expert(), "rllib_asor/LavaWorld-v0", 40, env_kwargs=LAVA)
    path = HERE / "lava-expert.npz"
    save_demonstrations(path, demos)
    rng = np.random.default_rng(0)
    random_score = lava_score(lambda o: int(rng.integers(4)), episodes_per_row=100)
    save_result(RESULTS, "gaifo/random", random_score)
    save_result(RESULTS, "gaifo/expert", lava_score(reactive_expert()))
    for seed in SEEDS:
        config = (
            GaifoConfig()
            .environment("rllib_asor/LavaWorld-v0", env_config=LAVA)
            .env_runners(num_env_runners=0, num_envs_per_env_runner=4)
            .training(
                lr=0.0005, gamma=0.99, lambda_=0.95, entropy_coeff=0.01,
                train_batch_size=2000, minibatch_size=256, num_epochs=6,
            )
            .rl_module(model_config={"fcnet_hiddens": [64, 64]})
            .gaifo(demonstrations=str(path), seed=seed, reward_form=reward_form)
            .debugging(seed=seed)
        )
        algo, t0 = config.build_algo(), time.time()
        try:
            while True:
                result = algo.train()
                if result["num_env_steps_sampled_lifetime"] >= 40_000:
                    break
            policy = module_policy(algo.get_module())
            score = lava_score(lambda o, p=policy: int(p(stack_obs([o]), None)[0]))
            row = {
                "score": score,
                "env_steps": int(result["num_env_steps_sampled_lifetime"]),
                "disc": {k: float(v) for k, v in result["learners"]["gaifo"].items()},
                "wall_s": round(time.time() - t0, 1),
            }
        finally:
            algo.stop()
        print(f"GAIfO ({reward_form}) seed {seed}: {row}")
        save_result(RESULTS, f"{tag}/seed{seed}", row)


# ----------------------------------------------------------------------------- GARAT
SOURCE, TARGET = {"g": 10.0}, {"g": 12.0}


def pendulum_ppo(config):
    from ray.rllib.connectors.env_to_module.mean_std_filter import MeanStdFilter

    return (
        config.env_runners(
            num_env_runners=0,
            num_envs_per_env_runner=4,
            env_to_module_connector=lambda env, spaces=None, device=None: MeanStdFilter(),
        )
        .training(
            lr=0.0003, gamma=0.95, lambda_=0.1, train_batch_size=512, minibatch_size=64,
            num_epochs=6, vf_clip_param=10.0,
        )
        .rl_module(model_config={"fcnet_activation": "relu"})
        .evaluation(evaluation_duration=20, evaluation_duration_unit="episodes",
                    evaluation_config={"explore": False})
    )


def train_and_score(config, steps: int = 60_000) -> dict:
    algo, t0 = config.build_algo(), time.time()
    try:
        while True:
            result = algo.train()
            if result["num_env_steps_sampled_lifetime"] >= steps:
                break
        target = algo.evaluate()["env_runners"]["episode_return_mean"]
        grounded = getattr(algo.config, "garat_grounded", None)
        return {
            "target_return": float(target),
            "source_train_return": float(result["env_runners"]["episode_return_mean"]),
            "wall_s": round(time.time() - t0, 1),
            "transformer": None if grounded is None else grounded["transformer"],
            "grounding": None if grounded is None else grounded["stats"],
        }
    finally:
        algo.stop()


def grounding_gap(transformer, n: int = 2000, seed: int = 0) -> dict:
    from rllib_asor.algorithms.garat.envs import GroundedEnv

    rng = np.random.default_rng(seed)
    target = gym.make("Pendulum-v1", **TARGET).unwrapped
    source = gym.make("Pendulum-v1", **SOURCE).unwrapped
    grounded = GroundedEnv({"env": "Pendulum-v1", "env_config": SOURCE, "transformer": transformer})
    for e in (target, source, grounded):
        e.reset(seed=seed)
    plain, fixed = [], []
    for _ in range(n):
        th, thdot, a = rng.uniform(-np.pi, np.pi), rng.uniform(-8, 8), rng.uniform(-2, 2, 1)
        nxt = []
        for e in (target, source):
            e.state = np.array([th, thdot])
            nxt.append(e.step(a.astype(np.float32))[0][2])
        grounded.env.unwrapped.state = np.array([th, thdot])
        grounded._s = np.array([np.cos(th), np.sin(th), thdot], np.float32)
        g = grounded.step(a.astype(np.float32))[0][2]
        plain.append(abs(nxt[1] - nxt[0]))
        fixed.append(abs(g - nxt[0]))
    return {"plain_gap": float(np.mean(plain)), "grounded_gap": float(np.mean(fixed))}


def garat() -> None:
    from ray.rllib.algorithms.ppo import PPOConfig

    from rllib_asor.algorithms.garat.config import GaratConfig

    rng = np.random.default_rng(0)
    demos = rollout_demonstrations(
        lambda o: rng.uniform(-2, 2, 1).astype(np.float32), "Pendulum-v1", 40, env_kwargs=TARGET
    )
    path = HERE / "pendulum-g12-random.npz"
    save_demonstrations(path, demos)
    env = gym.make("Pendulum-v1", **TARGET)
    rets = []
    for i in range(20):
        env.reset(seed=i)
        done, ret = False, 0.0
        while not done:
            _, r, term, trunc, _ = env.step(rng.uniform(-2, 2, 1).astype(np.float32))
            ret, done = ret + r, term or trunc
        rets.append(ret)
    save_result(RESULTS, "garat/random_target", float(np.mean(rets)))
    for seed in SEEDS:
        cfg = pendulum_ppo(
            GaratConfig()
            .environment("Pendulum-v1", env_config=SOURCE)
            .garat(demonstrations=str(path), target_env_config=TARGET, seed=seed,
                   grounding_iterations=30, grounding_batch_size=2000)
            .debugging(seed=seed)
        )
        row = train_and_score(cfg)
        row["gap"] = grounding_gap(row.pop("transformer"), seed=seed)
        print(f"GARAT seed {seed}: {row}")
        save_result(RESULTS, f"garat/seed{seed}", row)
        plain = pendulum_ppo(
            PPOConfig()
            .environment("Pendulum-v1", env_config=SOURCE)
            .evaluation(evaluation_config={"env_config": TARGET, "explore": False})
            .debugging(seed=seed)
        )
        row = train_and_score(plain)
        row.pop("transformer"), row.pop("grounding")
        print(f"PPO (plain source) seed {seed}: {row}")
        save_result(RESULTS, f"ppo_source/seed{seed}", row)


def pendulum_pi0(obs: np.ndarray, g: float = 10.0) -> np.ndarray:
    """π₀: energy-pumping swing-up, PD balance near the top (deterministic)."""
    c, s, thdot = (float(x) for x in obs)
    if c > 0.85:
        return np.clip([-(10.0 * np.arctan2(s, c) + 2.0 * thdot)], -2, 2).astype(np.float32)
    if abs(thdot) < 1e-3:
        return np.array([1.0], np.float32)
    energy = 0.5 * thdot**2 + 1.5 * g * c
    return np.clip([0.5 * thdot * (1.5 * g - energy)], -2, 2).astype(np.float32)


def pendulum_swing(obs: np.ndarray) -> np.ndarray:
    """Run 15's behaviour policy: deterministic, large torques (mean |a| 1.1 on its target rows,
    at the limit on about 40 % of them), all around the circle."""
    c, s, thdot = (float(x) for x in obs)
    return np.clip([4.0 * np.sin(3.0 * np.arctan2(s, c) + 0.5 * thdot)], -2, 2).astype(np.float32)


AUTHORS_SCHEDULE = {
    "disc_warmup_iterations": 3,
    "generator_iterations": 5,
    "transformer_epochs": 1,
    "transformer_clip_param": 0.1,
    "transformer_entropy_coeff": 0.01,
}
"""Run 10: the authors' schedule of the two players, scaled to 30 grounding iterations (README)."""


def target_pendulum(target_g: str, gain: float = 1.0, limit: bool = False) -> gym.Env:
    """The target Pendulum: gravity `target_g`, its torques scaled by `gain` before Pendulum
    clips them (run 14); with `limit`, in Pendulum-v1's 200-step time limit, else bare (the
    gap loops set its state). Gain 1: `gym.make("Pendulum-v1", g=...)` as runs 1-13."""
    from gymnasium.envs.classic_control.pendulum import PendulumEnv

    if gain == 1:
        env = gym.make("Pendulum-v1", g=float(target_g))
        return env if limit else env.unwrapped

    class GainPendulum(PendulumEnv):
        def step(self, u):
            return super().step(np.asarray(u, np.float32) * np.float32(gain))

    env = GainPendulum(g=float(target_g))
    return gym.wrappers.TimeLimit(env, 200) if limit else env


def _returns(env, act, episodes: int = 20) -> float:
    rets = []
    for i in range(episodes):
        obs, _ = env.reset(seed=i)
        done, ret = False, 0.0
        while not done:
            obs, r, term, trunc, _ = env.step(act(obs))
            ret, done = ret + r, term or trunc
        rets.append(ret)
    return float(np.mean(rets))


def garat_pi0(
    disc_steps: str = "5", disc_input: str = "s_next", grad_penalty: str = "1",
    disc_data: str = "rollouts", grad_penalty_form: str = "zero_centred", iterations: str = "30",
    target_g: str = "12", disc_norm: str = "target", schedule: str = "ours", batch: str = "2000",
    gamma: str = "0.99", init_std: str = "none", target_gain: str = "1", behaviour: str = "pi0",
    seeds: str = "0,1",
) -> None:
    """Run 2 (run 3: `disc_steps` 50; run 4: 50, `disc_input` s_a_delta, `grad_penalty` 0;
    run 5: run 4 with `disc_data` deterministic; run 6: run 5 with `grad_penalty` 10 of form
    one_centred_mix and 80 iterations; run 7: run 5 with 80 iterations; run 8: run 5 with the
    target's gravity 20; run 9: run 5 with `disc_norm` round; run 10: run 5 with `schedule`
    authors; run 11: run 5 with `batch` 5000; run 12: run 5 with the transformer's `gamma` 0;
    run 13: run 12 with `init_std` 0.1; run 14: run 5 with the target's gravity 10 and its
    torques scaled by `target_gain` 0.8; run 15: run 14 with `behaviour` swing and
    `target_gain` 0.5; run 16: run 15 on `seeds` 2,3): the grounding under a deterministic
    behaviour policy, π₀ or `pendulum_swing` (README.md)."""
    from rllib_asor.algorithms.common.demonstrations import load_demonstrations
    from rllib_asor.algorithms.garat.envs import GroundedEnv
    from rllib_asor.algorithms.garat.grounding import ground
    from rllib_asor.algorithms.garat.settings import GaratSettings

    gain = float(target_gain)
    act = {"pi0": pendulum_pi0, "swing": pendulum_swing}[behaviour]
    shift = ("" if target_g == "12" else f"_g{target_g}") + ("" if gain == 1 else f"_gain{target_gain}")
    path = HERE / f"pendulum-g{target_g}{'' if gain == 1 else f'-gain{target_gain}'}-{behaviour}.npz"
    save_demonstrations(
        path, rollout_demonstrations(act, target_pendulum(target_g, gain, limit=True), 20)
    )
    demos = load_demonstrations(path, gym.make("Pendulum-v1").observation_space)
    save_result(RESULTS, f"garat_pi0/{behaviour}{shift}", {
        "target": _returns(target_pendulum(target_g, gain, limit=True), act),
        "source": _returns(gym.make("Pendulum-v1", **SOURCE), act),
    })
    rng = np.random.default_rng(0)
    rows = rng.choice(len(demos), 2000, replace=False)
    for seed in (int(x) for x in seeds.split(",")):
        t0 = time.time()
        settings = GaratSettings(
            grounding_iterations=int(iterations), grounding_batch_size=int(batch), seed=seed,
            disc_steps=int(disc_steps), disc_input=disc_input, grad_penalty=float(grad_penalty),
            disc_data=disc_data, grad_penalty_form=grad_penalty_form, disc_norm=disc_norm,
            transformer_gamma=float(gamma),
            transformer_init_std=None if init_std == "none" else float(init_std),
            **AUTHORS_SCHEDULE if schedule == "authors" else {},
        )
        transformer, stats = ground("Pendulum-v1", SOURCE, settings, str(path), act)
        target = target_pendulum(target_g, gain)
        source = gym.make("Pendulum-v1", **SOURCE).unwrapped
        cfg = {"env": "Pendulum-v1", "env_config": SOURCE, "transformer": transformer}
        grounded = GroundedEnv(cfg)
        for e in (target, source, grounded):
            e.reset(seed=seed)
        plain, fixed = [], []
        for obs in demos.obs[rows]:
            th, thdot = float(np.arctan2(obs[1], obs[0])), float(obs[2])
            a = act(obs)
            nxt = []
            for e in (target, source):
                e.state = np.array([th, thdot])
                nxt.append(e.step(a)[0][2])
            grounded.env.unwrapped.state = np.array([th, thdot])
            grounded._s = obs.astype(np.float32)
            g = grounded.step(a)[0][2]
            plain.append(abs(nxt[1] - nxt[0]))
            fixed.append(abs(g - nxt[0]))
        row = {
            "plain_gap": float(np.mean(plain)),
            "grounded_gap": float(np.mean(fixed)),
            f"{behaviour}_in_grounded": _returns(GroundedEnv(cfg), act),
            "grounding": stats,
            "wall_s": round(time.time() - t0, 1),
        }
        tag = "garat_pi0" if disc_steps == "5" else f"garat_pi0_disc{disc_steps}"
        if (disc_input, grad_penalty) != ("s_next", "1"):
            tag += f"_{disc_input}_gp{grad_penalty}"
        if disc_data != "rollouts":
            tag += f"_{disc_data}"
        if grad_penalty_form != "zero_centred":
            tag += f"_{grad_penalty_form}"
        if iterations != "30":
            tag += f"_it{iterations}"
        if target_g != "12":
            tag += f"_g{target_g}"
        if disc_norm != "target":
            tag += f"_norm{disc_norm}"
        if schedule != "ours":
            tag += f"_schedule{schedule}"
        if batch != "2000":
            tag += f"_batch{batch}"
        if gamma != "0.99":
            tag += f"_gamma{gamma}"
        if init_std != "none":
            tag += f"_std{init_std}"
        if gain != 1:
            tag += f"_gain{target_gain}"
        if behaviour != "pi0":
            tag += f"_{behaviour}"
        print(f"GARAT pi0 ({disc_steps} D steps, {disc_input}, gp {grad_penalty}) seed {seed}: {row}")
        save_result(RESULTS, f"{tag}/seed{seed}", row)


def oracle_gap(target_g: str = "12") -> None:
    """The rule's floor: the one-step gap of garat_pi0's 2,000 target rows under the exact
    correction Δ = (g_target − g_source)/2 · sin θ (Pendulum-v1: θ̇′ = θ̇ + (3g/2 · sin θ + 3u)·dt
    with m = l = 1), clipped to the torque limit as the grounded env clips (README)."""
    from rllib_asor.algorithms.common.demonstrations import load_demonstrations

    g = float(target_g)
    demos = load_demonstrations(
        HERE / f"pendulum-g{target_g}-pi0.npz", gym.make("Pendulum-v1").observation_space
    )
    rows = np.random.default_rng(0).choice(len(demos), 2000, replace=False)
    target = target_pendulum(target_g)
    source = gym.make("Pendulum-v1", **SOURCE).unwrapped
    for e in (target, source):
        e.reset(seed=0)

    def thdot_next(env, th: float, thdot: float, a: np.ndarray) -> float:
        env.state = np.array([th, thdot])
        return float(env.step(a)[0][2])

    plain, oracle, saturated = [], [], 0
    for obs in demos.obs[rows]:
        th, thdot, a = float(np.arctan2(obs[1], obs[0])), float(obs[2]), pendulum_pi0(obs)
        ref = thdot_next(target, th, thdot, a)
        fixed = np.clip(a + (g - SOURCE["g"]) / 2 * np.sin(th), -2, 2).astype(np.float32)
        plain.append(abs(thdot_next(source, th, thdot, a) - ref))
        oracle.append(abs(thdot_next(source, th, thdot, fixed) - ref))
        saturated += int(abs(a[0]) >= 2)
    row = {
        "plain_gap": float(np.mean(plain)),
        "oracle_gap": float(np.mean(oracle)),
        "ratio": float(np.mean(oracle) / np.mean(plain)),
        "pi0_at_torque_limit": saturated / len(rows),
    }
    print(f"oracle (target g {target_g}): {row}")
    save_result(RESULTS, "garat_pi0/oracle" + ("" if target_g == "12" else f"_g{target_g}"), row)


if __name__ == "__main__":
    commands = {"gaifo": gaifo, "garat": garat, "garat_pi0": garat_pi0, "oracle_gap": oracle_gap}
    commands[sys.argv[1]](*sys.argv[2:])
