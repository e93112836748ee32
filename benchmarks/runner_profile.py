"""One race env runner's `sample()`: where its time goes, and env steps/s per setting.

The runner is RLlib's `SingleAgentEnvRunner`, built in this process (no Ray) from the config
of tuned_examples/race/ppo-asor-scale.yaml (race_net, all ten maps, 1,000-step episodes,
8 envs per runner; `benchmarks.scaling.race_config`), sampling with PPO's exploration policy
at its initial weights. One torch thread.

`--what split` times, around every call of one `sample(num_timesteps=N)` (wall clock and this
process's CPU time, after a warm-up sample): the vector env's `step` (RLlib's env step), of it
MuJoCo's `mj_step` (the physics) and the race env's own `step` (physics and its Python:
observations, rules, infos), the RLModule's `forward_exploration`, the env-to-module and
module-to-env connector pipelines; the rest of `sample()` is RLlib's loop: episodes (adding
each step, finishing and numpy-converting them), callbacks, metrics.

`--what profile` prints cProfile's top functions of one `sample()` (CPU time; the profiler
inflates Python-heavy parts).

`--what rate` measures env steps/s of one runner sampling for each `--variants` setting, the
variants built once and sampled in interleaved rounds (a fair ratio on a shared machine):

- `base`: the scale example's runner (8 envs, gymnasium's sync vector env);
- `envs16`, `envs32`: 16 or 32 envs per runner (`num_envs_per_env_runner`);
- `async`: 8 envs in gymnasium's async vector env (`gym_env_vectorize_mode="async"`: one
  subprocess per env; the steps run in parallel, RLlib's loop still waits for all of them);
- `async16`: the same with 16 envs;
- `eager`: the base runner acting with race_net's eager forward (`trace_inference: false`;
  the base runner acts through its TorchScript trace).

    python -m benchmarks.runner_profile --what split,rate --steps 2048 --rounds 3
"""

from __future__ import annotations

import argparse
import contextlib
import cProfile
import functools
import importlib
import json
import os
import pstats
import statistics
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

VARIANTS = {
    "base": {},
    "envs16": {"num_envs_per_env_runner": 16},
    "envs32": {"num_envs_per_env_runner": 32},
    "async": {"gym_env_vectorize_mode": "async"},
    "async16": {"gym_env_vectorize_mode": "async", "num_envs_per_env_runner": 16},
    "eager": {"model_config": {"trace_inference": False}},
    "fullinfo": {"env_config": {"step_info": "full"}},
    "rllib_unbatch": {"rllib_unbatch": True},
}
"""Each variant's `env_runners(...)` settings; `model_config` updates race_net's settings and
`env_config` the race env's (`fullinfo`: every step's info whole, as before `step_info`);
`rllib_unbatch` samples with RLlib's own `unbatch` (`ray_compat.fast_unbatch` undone while it
samples)."""
WHATS = ("split", "profile", "rate", "size", "infos")


def build_runner(variant: str = "base", algo: str = "asor") -> Any:
    """A `SingleAgentEnvRunner` with the scale example's settings and `variant`'s changes."""
    from ray.rllib.env.single_agent_env_runner import SingleAgentEnvRunner

    from benchmarks import scaling

    args = scaling.settle(scaling.build_parser().parse_args(["--runners", "1"]))
    config = scaling.race_config(algo, args, 0)
    settings = dict(VARIANTS[variant])
    settings.pop("rllib_unbatch", None)
    if "model_config" in settings:
        config = config.rl_module(
            model_config={**config.model_config, **settings.pop("model_config")}
        )
    if "env_config" in settings:
        config = config.environment(env_config={**config.env_config, **settings.pop("env_config")})
    config = config.env_runners(**settings)
    return SingleAgentEnvRunner(config=config)


def sample_n(runner: Any, n: int) -> int:
    """Sample at least `n` env steps; the number sampled."""
    done = 0
    while done < n:
        done += sum(len(e) for e in runner.sample(num_timesteps=n - done, random_actions=False))
    return done


class Timers:
    """Wall and CPU seconds summed per name, around wrapped callables."""

    def __init__(self) -> None:
        self.wall: dict[str, float] = {}
        self.cpu: dict[str, float] = {}
        self.calls: dict[str, int] = {}

    def wrap(self, name: str, fn: Any) -> Any:
        @functools.wraps(fn)
        def timed(*a: Any, **kw: Any) -> Any:
            t0, c0 = time.perf_counter(), time.process_time()
            try:
                return fn(*a, **kw)
            finally:
                self.wall[name] = self.wall.get(name, 0.0) + time.perf_counter() - t0
                self.cpu[name] = self.cpu.get(name, 0.0) + time.process_time() - c0
                self.calls[name] = self.calls.get(name, 0) + 1

        return timed


def split(steps: int, reps: int) -> dict[str, Any]:
    """`--what split` (see the module docstring): seconds per part for `reps` samples."""
    import mujoco

    import game_env.env
    import game_env.sim

    runner = build_runner()
    sample_n(runner, 512)  # warm-up
    t = Timers()
    vec = runner.env  # RLlib's DictInfoToList around gymnasium's vector env
    vec.step = t.wrap("env_step", vec.step)
    runner.module.forward_exploration = t.wrap("forward", runner.module.forward_exploration)
    e2m, m2e = runner._env_to_module, runner._module_to_env
    runner._env_to_module = _CallTimed(e2m, t.wrap("env_to_module", e2m.__call__))
    runner._module_to_env = _CallTimed(m2e, t.wrap("module_to_env", m2e.__call__))
    race_step = game_env.env.ObstacleRaceEnv.step
    game_env.env.ObstacleRaceEnv.step = t.wrap("race_env_step", race_step)
    mj_step = mujoco.mj_step
    game_env.sim.mujoco = _Namespace(mujoco, mj_step=t.wrap("mj_step", mj_step))
    walls, cpus, done = [], [], 0
    try:
        for _ in range(reps):
            t0, c0 = time.perf_counter(), time.process_time()
            done += sample_n(runner, steps)
            walls.append(time.perf_counter() - t0)
            cpus.append(time.process_time() - c0)
    finally:
        game_env.env.ObstacleRaceEnv.step = race_step
        game_env.sim.mujoco = mujoco
        runner.stop()
    return {"env_steps": done, "wall": sum(walls), "cpu": sum(cpus), "parts_wall": t.wall,
            "parts_cpu": t.cpu, "calls": t.calls}  # fmt: skip


class _CallTimed:
    """A connector pipeline whose `__call__` is timed (attributes pass through)."""

    def __init__(self, inner: Any, call: Any) -> None:
        self._inner, self._call = inner, call

    def __call__(self, *a: Any, **kw: Any) -> Any:
        return self._call(*a, **kw)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._inner, name)


class _Namespace:
    """A module seen through, with some attributes replaced."""

    def __init__(self, inner: Any, **over: Any) -> None:
        self._inner, self._over = inner, over

    def __getattr__(self, name: str) -> Any:
        return self._over[name] if name in self._over else getattr(self._inner, name)


SPLIT_ROWS = (
    ("sample", "`sample()`", 0),
    ("env_step", "vector env `step` (RLlib's env step)", 1),
    ("race_env_step", "the race env's own `step` (8 per vector step)", 2),
    ("mj_step", "MuJoCo `mj_step`: the physics", 3),
    ("race_python", "the race env's Python: observations, rules, infos", 3),
    ("vector_rest", "gymnasium's vector env and wrappers: obs stacking, infos merged and "
     "split again (`DictInfoToList`), autoreset", 2),
    ("forward", "RLModule `forward_exploration` (race_net on the batch of envs)", 1),
    ("env_to_module", "env-to-module connectors (obs batched, to torch)", 1),
    ("module_to_env", "module-to-env connectors (sample actions, to numpy, unbatch)", 1),
    ("loop_rest", "the rest of RLlib's loop: episodes, callbacks, metrics", 1),
)  # fmt: skip


def split_rows(res: dict[str, Any], key: str) -> dict[str, float]:
    """Seconds per `SPLIT_ROWS` part from `split()` (`key`: "wall" or "cpu")."""
    p = dict(res[f"parts_{key}"])
    p["sample"] = res[key]
    p["race_python"] = p.get("race_env_step", 0.0) - p.get("mj_step", 0.0)
    p["vector_rest"] = p.get("env_step", 0.0) - p.get("race_env_step", 0.0)
    p["loop_rest"] = p["sample"] - sum(
        p.get(k, 0.0) for k in ("env_step", "forward", "env_to_module", "module_to_env")
    )
    return p


def split_table(res: dict[str, Any]) -> str:
    wall, cpu = split_rows(res, "wall"), split_rows(res, "cpu")
    n = res["env_steps"]
    lines = [
        "| part of one runner's `sample()` | µs per env step (wall) | share (wall) "
        "| µs per env step (CPU) | share (CPU) |",
        "|---|---|---|---|---|",
    ]
    for key, label, depth in SPLIT_ROWS:
        name = "&nbsp;&nbsp;" * depth + (f"**{label}**" if depth == 0 else label)
        lines.append(
            f"| {name} | {1e6 * wall[key] / n:,.0f} | {100 * wall[key] / wall['sample']:.1f} % "
            f"| {1e6 * cpu[key] / n:,.0f} | {100 * cpu[key] / cpu['sample']:.1f} % |"
        )
    lines.append(
        f"| env steps/s of this runner | {n / res['wall']:,.0f} | | {n / res['cpu']:,.0f} "
        "per CPU second | |"
    )
    return "\n".join(lines) + "\n"


def profile(steps: int, top: int) -> str:
    """cProfile (CPU time) of one `sample()` after a warm-up: the top functions."""
    import io

    runner = build_runner()
    sample_n(runner, 512)
    prof = cProfile.Profile(timer=time.process_time)
    prof.enable()
    sample_n(runner, steps)
    prof.disable()
    runner.stop()
    out = io.StringIO()
    pstats.Stats(prof, stream=out).sort_stats("tottime").print_stats(top)
    return out.getvalue()


def size(steps: int) -> dict[str, Any]:
    """What one `sample()` of `steps` env steps hands to Ray for the driver: its episodes
    pickled as Ray pickles a task's result (protocol 5, numpy arrays as out-of-band buffers),
    the bytes and the CPU time to pickle and unpickle them (median of 5)."""
    import pickle

    from ray import cloudpickle

    runner = build_runner()
    try:
        sample_n(runner, 512)
        episodes = runner.sample(num_timesteps=steps, random_actions=False)
    finally:
        runner.stop()
    dumps, loads = [], []
    for _ in range(5):
        buffers: list[Any] = []
        t0 = time.process_time()
        meta = cloudpickle.dumps(episodes, protocol=5, buffer_callback=buffers.append)
        dumps.append(time.process_time() - t0)
        t0 = time.process_time()
        pickle.loads(meta, buffers=buffers)
        loads.append(time.process_time() - t0)
    return {
        "episodes": len(episodes),
        "env_steps": sum(len(e) for e in episodes),
        "pickle_bytes": len(meta),
        "buffer_bytes": sum(b.raw().nbytes for b in buffers),
        "dumps_ms": 1000 * statistics.median(dumps),
        "loads_ms": 1000 * statistics.median(loads),
    }


def infos(steps: int, rounds: int, envs: int = 8) -> dict[str, list[float]]:
    """CPU µs per env step of a runner's vector env alone (gymnasium's sync vector env and
    RLlib's `DictInfoToList` over `envs` race envs, random maps, the same random actions) with
    the race's `step_info` "full" and "lean", the two in turn in each round (same courses)."""
    import gymnasium as gym
    import numpy as np
    from gymnasium.wrappers.vector import DictInfoToList

    from rllib_asor.race.config import make_single_race_env

    def vector_env(mode: str) -> Any:
        cfg = {"map_id": "random", "max_episode_steps": 1000, "step_info": mode}
        return DictInfoToList(gym.vector.SyncVectorEnv([lambda: make_single_race_env(cfg)] * envs))

    venvs = {mode: vector_env(mode) for mode in ("full", "lean")}
    rng = np.random.default_rng(0)
    nvec = venvs["full"].single_action_space.nvec
    actions = rng.integers(0, nvec, size=(64, envs, len(nvec)))
    out: dict[str, list[float]] = {mode: [] for mode in venvs}
    try:
        for r in range(rounds):
            for mode, venv in venvs.items():
                venv.reset(seed=r)
                n = max(steps // envs, 1)
                t0 = time.process_time()
                for i in range(n):
                    venv.step(actions[i % 64])
                out[mode].append(1e6 * (time.process_time() - t0) / (n * envs))
    finally:
        for venv in venvs.values():
            venv.close()
    return out


@contextlib.contextmanager
def rllib_unbatch(on: bool) -> Iterator[None]:
    """While on: the per-step callers of `unbatch` use RLlib's own (`ray_compat._UNBATCH_USERS`)."""
    from ray.rllib.utils.spaces.space_utils import unbatch

    from rllib_asor import ray_compat

    modules = [(importlib.import_module(m), name) for m, name in ray_compat._UNBATCH_USERS]
    saved = [getattr(m, name) for m, name in modules]
    try:
        if on:
            for m, name in modules:
                setattr(m, name, unbatch)
        yield
    finally:
        for (m, name), fn in zip(modules, saved, strict=True):
            setattr(m, name, fn)


def rate(variants: list[str], steps: int, rounds: int) -> dict[str, Any]:
    """Env steps/s (wall, and per CPU second of this process) of each variant's runner, the
    variants sampled in turn in each round after a warm-up sample each."""
    runners = {v: build_runner(v) for v in variants}
    rows: dict[str, dict[str, list[float]]] = {v: {"wall": [], "cpu": []} for v in variants}
    try:
        for r in runners.values():
            sample_n(r, 512)
        for _ in range(rounds):
            for v, r in runners.items():
                t0, c0 = time.perf_counter(), time.process_time()
                with rllib_unbatch(VARIANTS[v].get("rllib_unbatch", False)):
                    n = sample_n(r, steps)
                rows[v]["wall"].append(n / (time.perf_counter() - t0))
                rows[v]["cpu"].append(n / max(time.process_time() - c0, 1e-9))
    finally:
        for r in runners.values():
            r.stop()
    return rows


def rate_table(rows: dict[str, dict[str, list[float]]]) -> str:
    base = statistics.median(rows["base"]["wall"]) if "base" in rows else None
    lines = [
        "| runner setting | env steps/s (median of rounds) | per round | ÷ base | "
        "per CPU second of the runner's process |",
        "|---|---|---|---|---|",
    ]
    for v, r in rows.items():
        med = statistics.median(r["wall"])
        lines.append(
            f"| {v} ({json.dumps(VARIANTS[v]) if VARIANTS[v] else 'the scale example'}) "
            f"| {med:,.0f} | {', '.join(f'{x:.0f}' for x in r['wall'])} "
            f"| {med / base:.2f} | {statistics.median(r['cpu']):,.0f} |"
            if base
            else f"| {v} | {med:,.0f} | | | |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--what", default="split,rate", help="comma list of " + ",".join(WHATS))
    p.add_argument("--variants", default="base,envs16,envs32,async")
    p.add_argument("--steps", type=int, default=2048, help="env steps per sample/round")
    p.add_argument("--reps", type=int, default=2, help="samples timed by --what split")
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--top", type=int, default=40)
    p.add_argument("--out", default="benchmarks/out/runner_profile")
    args = p.parse_args(argv)
    whats = [w for w in args.what.split(",") if w]
    variants = [v for v in args.variants.split(",") if v]
    bad = [w for w in whats if w not in WHATS] + [v for v in variants if v not in VARIANTS]
    if bad or not whats:
        print(
            f"runner_profile: {bad or args.what!r} is invalid: allowed --what of "
            f"{', '.join(WHATS)}, --variants of {', '.join(VARIANTS)}",
            file=sys.stderr,
        )
        return 2
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    import torch

    torch.set_num_threads(1)
    from rllib_asor.race.config import register_race_envs

    register_race_envs()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results: dict[str, Any] = {"settings": vars(args), "cpus": os.cpu_count()}
    if "split" in whats:
        results["split"] = split(args.steps, args.reps)
        print(split_table(results["split"]), flush=True)
    if "profile" in whats:
        text = profile(args.steps, args.top)
        (out / "profile.txt").write_text(text)
        print(text, flush=True)
    if "rate" in whats:
        results["rate"] = rate(variants, args.steps, args.rounds)
        print(rate_table(results["rate"]), flush=True)
    if "infos" in whats:
        results["infos"] = infos(args.steps, args.rounds)
        for mode, per_round in results["infos"].items():
            print(f"step_info {mode}: CPU µs per env step of the vector env, median "
                  f"{statistics.median(per_round):.0f} ({', '.join(f'{x:.0f}' for x in per_round)})")
    if "size" in whats:
        results["size"] = r = size(args.steps)
        print(
            f"one sample() of {r['env_steps']} env steps ({r['episodes']} episode chunks): "
            f"{r['buffer_bytes'] / 1e6:.2f} MB of arrays + {r['pickle_bytes'] / 1e3:.0f} kB "
            f"pickled around them; pickled in {r['dumps_ms']:.1f} ms, unpickled in "
            f"{r['loads_ms']:.1f} ms (CPU)",
            flush=True,
        )
    (out / "runner_profile.json").write_text(json.dumps(results, indent=1, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
