"""MAPLE+DARA against MAPLE on SlipEnv's mixed-dynamics data (README.md: question and rule, fixed first).

OMP_NUM_THREADS=1 nice .venv/bin/python studies/dara_check/run.py [--iters N] [--seeds 0 1 2]

Each finished run is saved to runs/<method>-seed<k>.json.gz at once; a rerun skips it
(summarise.py: the table and the rule's verdicts). The stand-in datasets
are written under data/ beside this file (`make_data`, seed fixed, the same for every run).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

from studies.lib.run_files import existing, run_file, write_run

HERE = Path(__file__).resolve().parent
DATA = HERE / "data"
RUNS = HERE / "runs"
ENV_ID = "dara_check/Slip-v0"
METHODS = ("maple", "maple_dara")
T, GOAL, LIMIT = 20, 6.0, 10.0
EVAL_EPISODES = 20
EPISODES = {"original": 25, "boost": 100}
"""Episodes of each dynamics in the data: scarce target (original), plentiful source (boost)."""
DARA_ARMS = {
    "maple_dara": {"eta": 0.1},
    "maple_dara_eta1": {"eta": 1.0},
    "maple_dara_eta3": {"eta": 3.0},
    "maple_dara_noise01": {"eta": 0.1, "input_noise": 0.1},
    "maple_dara_eta1_noise01": {"eta": 1.0, "input_noise": 0.1},
}
"""DARA's settings per arm (README): `maple_dara` (shipped η 0.1, classifier input noise σ 1) is
the first rule's; the next three are exploratory; `maple_dara_eta1_noise01` is the
confirmatory rule's."""


DATA_STARTS = {"": (-0.5, 0.5), "cover": (-1.0, 10.0)}
"""Start states of the data's episodes: the task's own, and `cover` (the coverage rule, README):
spread over the track, so the target's data reaches the states the source's data visits."""


class SlipEnv(gym.Env):
    """x ← x + a for a ≤ 0.5; above 0.5 the target (`original`) slips back (x − 1), the source
    (`boost`) jumps (x + 2a). Reward 1 − |x′ − 6|/6, 20 steps, x0 ~ U(start) (U(−0.5, 0.5)),
    |x| ≤ 10."""

    observation_space = gym.spaces.Box(-LIMIT, LIMIT, (2,), np.float32)
    action_space = gym.spaces.Box(-1, 1, (1,), np.float32)

    def __init__(
        self, dynamics: str = "original", seed: int = 0, start: tuple[float, float] = (-0.5, 0.5)
    ) -> None:
        if dynamics not in EPISODES:
            raise ValueError(f"dynamics={dynamics!r} is invalid: allowed {' | '.join(EPISODES)}")
        self.dynamics, self.start = dynamics, start
        self._rng = np.random.default_rng(seed)

    def _obs(self) -> np.ndarray:
        return np.array([self.x, self.t / T], np.float32)

    def reset(self, *, seed=None, options=None):
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        self.x, self.t = float(self._rng.uniform(*self.start)), 0
        return self._obs(), {}

    def step(self, action):
        a = float(np.clip(np.asarray(action, dtype=np.float64).reshape(-1)[0], -1, 1))
        if a <= 0.5:
            dx = a
        else:
            dx = -1.0 if self.dynamics == "original" else 2.0 * a
        self.x = float(np.clip(self.x + dx, -LIMIT, LIMIT))
        self.t += 1
        return self._obs(), 1.0 - abs(self.x - GOAL) / GOAL, False, self.t >= T, {}


def register() -> None:
    """The env id (its name holds `slip`) and MAPLE's model-rollout rule for it (never ends)."""
    from rllib_asor.algorithms.maple.termination import register_termination

    if ENV_ID not in gym.registry:
        gym.register(ENV_ID, entry_point=SlipEnv)
    register_termination("slip", lambda o: ~np.isfinite(o).all(-1))


def rollout(
    policy, dynamics: str, episodes: int, seed: int, start: tuple[float, float] = (-0.5, 0.5)
) -> list[tuple]:
    """(obs [T+1], actions [T], rewards [T]) of `episodes` episodes; policy(obs, rng) -> a."""
    env, rng, out = SlipEnv(dynamics, seed, start), np.random.default_rng(seed + 1), []
    for e in range(episodes):
        obs, _ = env.reset(seed=seed * 1000 + e)
        o, a, r = [obs], [], []
        done = False
        while not done:
            act = np.asarray(policy(obs, rng), np.float32).reshape(1)
            obs, rew, term, trunc, _ = env.step(act)
            o.append(obs), a.append(act), r.append(rew)
            done = term or trunc
        out.append((np.array(o), np.array(a), np.array(r, np.float32)))
    return out


def behaviour(seed: int):
    """The data's policy: a per-episode level c ~ U(−0.3, 1) plus N(0, 0.3) noise per step."""
    level = {"c": 0.0}

    def policy(obs: np.ndarray, rng: np.random.Generator) -> float:
        if obs[1] == 0.0:
            level["c"] = rng.uniform(-0.3, 1.0)
        return float(np.clip(level["c"] + 0.3 * rng.normal(), -1, 1))

    return policy


def reference_policies() -> dict:
    """Uniform random, never moving (a = 0), and the target's best (a = 0.5 towards the goal,
    then hold)."""
    return {
        "random": lambda obs, rng: rng.uniform(-1, 1),
        "still": lambda obs, rng: 0.0,
        "optimal": lambda obs, rng: float(np.clip(GOAL - obs[0], -1, 0.5)),
    }


def make_data(variant: str = "") -> list[str]:
    """The two parts `data/slip/<dynamics>/mixed` (parquet rows of SingleAgentEpisode states,
    `rllib data collect`'s layout), made once with seed 0 and 1; `variant` "cover":
    `data/slip_cover/...`, the same but every episode starts at x0 ~ U(DATA_STARTS["cover"])."""
    import msgpack
    import msgpack_numpy as mnp
    import pyarrow as pa
    import pyarrow.parquet as pq
    from ray.rllib.env.single_agent_episode import SingleAgentEpisode

    parts = []
    for i, (dyn, n) in enumerate(EPISODES.items()):
        part = DATA / "_".join(filter(None, ("slip", variant))) / dyn / "mixed"
        parts.append(str(part))
        if (part / "part-00000.parquet").is_file():
            continue
        rows = []
        for obs, acts, rews in rollout(behaviour(i), dyn, n, seed=i, start=DATA_STARTS[variant]):
            ep = SingleAgentEpisode(
                observation_space=SlipEnv.observation_space,
                action_space=SlipEnv.action_space,
            )
            ep.add_env_reset(obs[0])
            for k in range(len(acts)):
                ep.add_env_step(obs[k + 1], acts[k], float(rews[k]), truncated=k == len(acts) - 1)
            rows.append(msgpack.packb(ep.get_state(), default=mnp.encode))
        part.mkdir(parents=True, exist_ok=True)
        pq.write_table(pa.table({"item": pa.array(rows, type=pa.binary())}),
                       (part / "part-00000.parquet").as_posix())  # fmt: skip
    return parts


def config(method: str, seed: int, parts: list[str], cache: Path):
    """MAPLE (the paper's settings, the TF MAPLE's smaller ensemble, this check's budget),
    with DARA's settings of the arm (DARA_ARMS) for `maple_dara*`."""
    import rllib_asor
    from rllib_asor.algorithms.dara.wiring import with_dara

    cfg = (
        rllib_asor.MapleConfig()
        .environment(ENV_ID, env_config={"dynamics": "original"})
        .offline_data(input_=parts)
        .maple(
            ensemble="tf_maple",
            horizon=10,
            penalty_coef=0.25,
            rollout_batch_size=2000,
            steps_per_iteration=250,
            gru_hidden=32,
            context_dim=8,
            hiddens=[64, 64],
            evaluation_interval=0,
            ensemble_cache=str(cache / "ensembles"),
        )
        .training(train_batch_size_per_learner=64)
        .debugging(seed=seed, log_level="ERROR")
    )
    if method.startswith("maple_dara"):
        settings = DARA_ARMS[method]
        cfg = with_dara(cfg, target_dynamics="original", cache=str(cache / "dara"), **settings)
    return cfg


def maple_policy(algo):
    """The trained MAPLE policy, deterministic, its GRU context stepped (MAPLE's evaluation)."""
    from rllib_asor.algorithms.maple.evaluation import maple_actor

    nets = algo._module().nets
    nets.eval()
    actor = maple_actor(nets)
    state = {"step": None}

    def policy(obs: np.ndarray, rng: np.random.Generator) -> float:
        if obs[1] == 0.0:
            state["step"] = actor()
        return state["step"](obs, {})

    return policy


def score(policy, seed: int) -> float:
    """Mean return of EVAL_EPISODES episodes under the target dynamics (start seeds fixed)."""
    return float(np.mean([r.sum() for _, _, r in rollout(policy, "original", EVAL_EPISODES,
                                                             10_000 + seed)]))  # fmt: skip


def run(method: str, seed: int, iters: int, parts: list[str]) -> dict:
    if method in reference_policies():
        return {"score": score(reference_policies()[method], seed), "seconds": 0.0}
    t0 = time.perf_counter()
    algo = config(method, seed, parts, DATA / "cache").build_algo()
    try:
        for _ in range(iters):
            result = algo.train()
        out = {"score": score(maple_policy(algo), seed)}
        if "dara" in result:
            out["dara"] = {k: float(v) for k, v in result["dara"].items()}
    finally:
        algo.stop()
    return {**out, "seconds": time.perf_counter() - t0}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--iters", type=int, default=50)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--methods", nargs="+", default=["random", "optimal", *METHODS])
    args = parser.parse_args()
    import ray
    import torch

    torch.set_num_threads(1)
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    register()
    RUNS.mkdir(exist_ok=True)
    for seed in args.seeds:
        for method in args.methods:
            path = run_file(RUNS, f"{method}-seed{seed}")
            if existing(path):
                continue
            result = {"method": method, "seed": seed, "iters": args.iters}
            arm, _, variant = method.partition("+")  # `maple+cover`: MAPLE on the `cover` data
            result.update(run(arm, seed, args.iters, make_data(variant)))
            write_run(path, result)
            print(path.name, json.dumps(result), flush=True)
    from summarise import summarise, table

    print(table(summarise(RUNS)))


if __name__ == "__main__":
    main()
