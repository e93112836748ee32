"""BCO and SOIL imitating the lava world's expert from its states (README.md beside this file).

python studies/bco_soil_check/run.py bco     # then: ... run.py soil
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

import rllib_asor  # noqa: F401  (registers our env ids)
from rllib_asor.algorithms.common.demonstrations import (
    Demonstrations,
    rollout_demonstrations,
    save_demonstrations,
)
from rllib_asor.envs.lava import reactive_expert
from rllib_asor.evaluation.rollout import module_policy, policy_module, stack_obs
from studies.lib.lava_imitation import LAVA, lava_score, save_result

HERE = Path(__file__).parent
RESULTS = HERE / "results.json"
DEMOS = HERE / "lava-expert.npz"
SEEDS = (0, 1)
PPO_LAVA = dict(
    lr=0.0005, gamma=0.99, lambda_=0.95, entropy_coeff=0.01, train_batch_size_per_learner=2000,
    minibatch_size=256, num_epochs=6,
)  # fmt: skip
"""tuned_examples/lava/ppo.yaml's PPO settings."""


def greedy(algo):
    policy = module_policy(policy_module(algo))
    return lambda obs: int(policy(stack_obs([obs]))[0])


def demonstrations() -> Demonstrations:
    demos = rollout_demonstrations(reactive_expert(), "rllib_asor/LavaWorld-v0", 40, env_kwargs=LAVA)
    save_demonstrations(DEMOS, demos)
    return demos


def baselines() -> None:
    rng = np.random.default_rng(0)
    save_result(RESULTS, "random", lava_score(lambda o: int(rng.integers(4)), episodes_per_row=100))
    save_result(RESULTS, "expert", lava_score(reactive_expert()))


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
            truth = np.array([reactive_expert()(o) for o in demos.obs])
            run = {
                "score": lava_score(greedy(algo)),
                "idm_accuracy_on_expert": float((labels == truth).mean()),
                "env_steps": int(result["env_runners"]["num_env_steps_sampled_lifetime"]),
                "seconds": round(time.perf_counter() - t0, 1),
            }
        finally:
            algo.stop()
        save_result(RESULTS, f"bco/seed{seed}", run)
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
        save_result(RESULTS, f"{arm}/seed{seed}", run)
        print(arm, seed, run, flush=True)


if __name__ == "__main__":
    import ray

    ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False)
    which = sys.argv[1] if len(sys.argv) > 1 else "bco"
    {"bco": bco, "soil": lambda: soil("soil"), "ppo": lambda: soil("ppo")}[which]()
