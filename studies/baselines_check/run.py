"""OSI and CaDM against SAC on GainEnv (README.md: the question and the rule, fixed first).

OMP_NUM_THREADS=1 nice .venv/bin/python studies/baselines_check/run.py [--steps 3000]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

HERE = Path(__file__).resolve().parent
METHODS = ("random", "sac", "osi", "cadm")


class GainEnv(gym.Env):
    """x ← clip(x + 0.2·g·a, ±10), reward −|x|, 20 steps; g ∈ (−1, 0.5, 2) per episode."""

    GAINS = (-1.0, 0.5, 2.0)
    observation_space = gym.spaces.Box(-10, 10, (2,), np.float32)
    action_space = gym.spaces.Box(-1, 1, (1,), np.float32)

    def __init__(self, config=None) -> None:
        self._rng = np.random.default_rng((config or {}).get("seed", 0))

    def _info(self) -> dict:
        return {"dynamics_id": self.task, "dynamics_params": np.array([self.GAINS[self.task] / 2])}

    def reset(self, *, seed=None, options=None):
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        self.task, self.x, self.t = int(self._rng.integers(3)), 1.0, 0
        return np.array([self.x, 0.0], np.float32), self._info()

    def step(self, action):
        self.x = float(np.clip(self.x + self.GAINS[self.task] * float(action[0]) * 0.2, -10, 10))
        self.t += 1
        obs = np.array([self.x, self.t / 20], np.float32)
        return obs, -abs(self.x), False, self.t >= 20, self._info()


def config(method: str, seed: int, steps: int):
    """The RLlib config of one method (README's budget)."""
    if method == "sac":
        from rllib_asor.algorithms.sac.config import FastSACConfig

        cfg = FastSACConfig().rl_module(
            model_config={"fcnet_hiddens": [128, 64], "fcnet_activation": "relu"}
        )
    elif method == "osi":
        from rllib_asor.algorithms.osi.config import OsiConfig

        cfg = OsiConfig().osi(history_len=4, param_dim=1)
    else:
        from rllib_asor.algorithms.cadm.config import CadmConfig

        cfg = CadmConfig().cadm(history_len=4)
    return (
        cfg.environment(GainEnv, env_config={"seed": seed})
        .env_runners(num_env_runners=0)
        .training(num_steps_sampled_before_learning_starts=500, train_batch_size_per_learner=64)
        .reporting(min_sample_timesteps_per_iteration=500)
        .evaluation(
            evaluation_interval=None,
            evaluation_duration=30,
            evaluation_duration_unit="episodes",
            evaluation_num_env_runners=0,
            evaluation_config={"explore": False, "env_config": {"seed": 10_000 + seed}},
        )
        .debugging(seed=seed, log_level="ERROR")
    )


def random_score(seed: int, episodes: int = 30) -> float:
    env, rng, total = GainEnv({"seed": 10_000 + seed}), np.random.default_rng(seed), 0.0
    for _ in range(episodes):
        env.reset()
        done = False
        while not done:
            _, r, term, trunc, _ = env.step(rng.uniform(-1, 1, size=1))
            total += r
            done = term or trunc
    return total / episodes


def run(method: str, seed: int, steps: int) -> dict:
    if method == "random":
        return {"score": random_score(seed), "seconds": 0.0}
    t0 = time.perf_counter()
    algo = config(method, seed, steps).build_algo()
    try:
        while True:
            result = algo.train()
            if result["num_env_steps_sampled_lifetime"] >= steps:
                break
        score = algo.evaluate()["env_runners"]["episode_return_mean"]
    finally:
        algo.stop()
    return {"score": float(score), "seconds": time.perf_counter() - t0}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    parser.add_argument("--methods", nargs="+", default=list(METHODS))
    args = parser.parse_args()
    import ray

    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    out = HERE / "results.json"
    results = json.loads(out.read_text()) if out.is_file() else {}
    for method in args.methods:
        for seed in args.seeds:
            key = f"{method}/seed{seed}"
            if key in results:
                continue
            results[key] = {"steps": args.steps, **run(method, seed, args.steps)}
            print(key, results[key], flush=True)
            out.write_text(json.dumps(results, indent=1, sort_keys=True) + "\n")
    for method in args.methods:
        scores = [results[f"{method}/seed{s}"]["score"] for s in args.seeds]
        print(f"{method:7s} mean {np.mean(scores):7.2f}  seeds {np.round(scores, 2).tolist()}")


if __name__ == "__main__":
    main()
