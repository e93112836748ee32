"""BCO and SOIL imitating the lava world's expert from its states (README.md beside this file).

python studies/bco_soil_check/run.py bco     # then: ... run.py soil
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

import rllib_asor  # noqa: F401  (registers our env ids)
from rllib_asor.algorithms.common.demonstrations import (
    Demonstrations,
    rollout_demonstrations,
    save_demonstrations,
)
from rllib_asor.evaluation.rollout import module_policy, policy_module, stack_obs

HERE = Path(__file__).parent
RESULTS = HERE / "results.json"
DEMOS = HERE / "lava-expert.npz"
LAVA = {"obs_mode": "onehot", "layout": "B"}
SEEDS = (0, 1)
PPO_LAVA = dict(
    lr=0.0005, gamma=0.99, lambda_=0.95, entropy_coeff=0.01, train_batch_size_per_learner=2000,
    minibatch_size=256, num_epochs=6,
)  # fmt: skip
"""tuned_examples/lava/ppo.yaml's PPO settings."""


def _save(key: str, value: object) -> None:
    data = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}
    data[key] = value
    RESULTS.write_text(json.dumps(data, indent=1))


def lava_expert():
    from rllib_asor.envs.lava import GRID_SIZE, best_reactive_policy

    table = best_reactive_policy("B")

    def act(obs):
        row, col = int(np.argmax(obs[:GRID_SIZE])), int(np.argmax(obs[GRID_SIZE : 2 * GRID_SIZE]))
        return table[(row, col, bool(obs[-1] > 0.5))]

    return act


def lava_score(act, episodes_per_row: int = 1, seed: int = 0) -> float:
    env = gym.make("rllib_asor/LavaWorld-v0", **LAVA)
    total, n = 0.0, 0
    for k in (2, 3, 4, 5):
        for i in range(episodes_per_row):
            obs, _ = env.reset(seed=seed + i, options={"lava_row": k})
            done, ret = False, 0.0
            while not done:
                obs, r, term, trunc, _ = env.step(act(obs))
                ret, done = ret + r, term or trunc
            total, n = total + ret, n + 1
    return total / n


def greedy(algo):
    policy = module_policy(policy_module(algo))
    return lambda obs: int(policy(stack_obs([obs]))[0])


def demonstrations() -> Demonstrations:
    demos = rollout_demonstrations(lava_expert(), "rllib_asor/LavaWorld-v0", 40, env_kwargs=LAVA)
    save_demonstrations(DEMOS, demos)
    return demos


def baselines() -> None:
    rng = np.random.default_rng(0)
    _save("random", lava_score(lambda o: int(rng.integers(4)), episodes_per_row=100))
    _save("expert", lava_score(lava_expert()))


def bco() -> None:
    from rllib_asor.algorithms.bco.config import BcoConfig

    demos = demonstrations()
    baselines()
    for seed in SEEDS:
        config = (
            BcoConfig()
            .environment("rllib_asor/LavaWorld-v0", env_config=LAVA)
            .env_runners(num_env_runners=0, num_envs_per_env_runner=4)
            .training(lr=1e-3, train_batch_size_per_learner=64)
            .bco(demonstrations=str(DEMOS), alpha=0.5, pre_demo_steps=2000, idm_steps=1000,
                 idm_batch_size=64, bc_epochs=10, seed=seed)
            .debugging(seed=seed)
        )  # fmt: skip
        t0 = time.perf_counter()
        algo = config.build_algo()
        try:
            for _ in range(6):
                result = algo.train()
            labels = algo.idm.infer(demos.obs, demos.next_obs).cpu().numpy()
            truth = np.array([lava_expert()(o) for o in demos.obs])
            run = {
                "score": lava_score(greedy(algo)),
                "idm_accuracy_on_expert": float((labels == truth).mean()),
                "env_steps": int(result["env_runners"]["num_env_steps_sampled_lifetime"]),
                "seconds": round(time.perf_counter() - t0, 1),
            }
        finally:
            algo.stop()
        _save(f"bco/seed{seed}", run)
        print("bco", seed, run, flush=True)


def soil(arm: str = "soil") -> None:
    from ray.rllib.algorithms.ppo import PPOConfig

    from rllib_asor.algorithms.soil.config import SoilConfig

    demonstrations()
    baselines()
    for seed in SEEDS:
        base = SoilConfig() if arm == "soil" else PPOConfig()
        config = (
            base.environment("rllib_asor/LavaWorld-v0", env_config=LAVA)
            .env_runners(num_env_runners=0, num_envs_per_env_runner=4)
            .training(**PPO_LAVA)
            .rl_module(model_config={"fcnet_hiddens": [64, 64]})
            .debugging(seed=seed)
        )
        if arm == "soil":
            config.soil(demonstrations=str(DEMOS), seed=seed)
        t0 = time.perf_counter()
        algo = config.build_algo()
        try:
            steps = 0
            while steps < 40_000:
                result = algo.train()
                steps = int(result["env_runners"]["num_env_steps_sampled_lifetime"])
            run = {
                "score": lava_score(greedy(algo)),
                "env_steps": steps,
                "seconds": round(time.perf_counter() - t0, 1),
            }
            if arm == "soil":
                run["idm_accuracy"] = result["learners"]["soil"].get("idm_accuracy")
        finally:
            algo.stop()
        _save(f"{arm}/seed{seed}", run)
        print(arm, seed, run, flush=True)


if __name__ == "__main__":
    import ray

    ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False)
    which = sys.argv[1] if len(sys.argv) > 1 else "bco"
    {"bco": bco, "soil": lambda: soil("soil"), "ppo": lambda: soil("ppo")}[which]()
