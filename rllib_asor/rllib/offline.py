"""Offline datasets for cross-dynamics RL (D4RL-like), loading them into CQL, normalised scores.

Layout written by `python -m rllib_asor.rllib.offline collect` (nothing is downloaded)::

    <out>/<task>/manifest.json                  return statistics, reference returns, provenance
    <out>/<task>/<dynamics>/<quality>/*.parquet one row per complete episode (column "item":
                                                the episode's state packed with msgpack_numpy,
                                                RLlib's `output_write_episodes=True` format)
    <out>/<task>/<dynamics>/policies/<name>/    RLModule checkpoints of the policies used

`task` is the env id's short name (`rllib_asor/HopperShift-v0` -> `hopper`); `dynamics` are
presets of `MujocoShiftEnv` (`original`, `body_mass` = mass x3, `density_10`); `quality` is
`random` (uniform actions), `medium` (a partially trained policy), `expert` (the best policy
of the run) or `medium-replay` (what training saw up to the medium snapshot). Policies are
trained per dynamics with PPO (default; ~10x cheaper per env step than RLlib's SAC on a small
CPU machine) or SAC (`--trainer`), for `--train-steps` env steps.

Normalised score (D4RL): 100 * (R - R_random) / (R_expert - R_random) with our own random and
expert datasets' mean episode returns under the same dynamics.

A task directory is written into a temporary sibling and renamed when complete, so a crash
leaves no half-written dataset behind.
"""

from __future__ import annotations

import argparse
import copy
import datetime as _dt
import json
import logging
import math
import os
import re
import shutil
import sys
import tempfile
import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

FORMAT = "rllib_asor.offline/v1"
MANIFEST = "manifest.json"
QUALITIES = ("random", "medium", "expert", "medium-replay")
DYNAMICS = ("original", "body_mass", "density_10")
POLICY_QUALITIES = ("medium", "expert")
TRAINERS = ("ppo", "sac")
_HINT = "expected a dataset written by `python -m rllib_asor.rllib.offline collect`"


def task_name(env_id: str) -> str:
    """Short task name of an env id: `rllib_asor/HopperShift-v0` -> `hopper`."""
    base = env_id.rsplit("/", 1)[-1]
    base = re.sub(r"-v\d+$", "", base)
    base = re.sub(r"Shift$", "", base)
    return base.lower()


# ------------------------------------------------------------------------------ collecting
@dataclass
class PolicySnapshot:
    """One policy state taken after a training iteration."""

    env_steps: int
    train_return: float
    num_replay_episodes: int
    state: dict[str, Any] = field(repr=False)


@dataclass
class TrainRun:
    """Result of `train_policy`: per-iteration snapshots, and for SAC its replay episodes."""

    snapshots: list[PolicySnapshot]
    replay_episodes: list[Any] | None
    seconds: float

    def pick(self) -> dict[str, PolicySnapshot]:
        """expert = best training return; medium = the first snapshot that reaches a third of
        the way from the first snapshot's return to the expert's (D4RL's "medium" is about a
        third of expert performance), never after the expert."""
        if not self.snapshots:
            raise ValueError("training run has no snapshots; increase --train-steps")
        finite = [s for s in self.snapshots if math.isfinite(s.train_return)]
        if not finite:
            last = self.snapshots[-1]
            return {"medium": self.snapshots[len(self.snapshots) // 2], "expert": last}
        expert = max(finite, key=lambda s: s.train_return)
        low = finite[0].train_return
        target = low + (expert.train_return - low) / 3.0
        medium = next(
            (s for s in finite if s.train_return >= target and s.env_steps <= expert.env_steps),
            expert,
        )
        return {"medium": medium, "expert": expert}


def sac_config(env_id: str, dynamics: str, steps: int, seed: int) -> Any:
    """A small SAC config (local env runner, local learner) for `steps` env steps."""
    from ray.rllib.algorithms.sac import SACConfig

    warmup = max(1, min(1000, steps // 5))
    return (
        SACConfig()
        .environment(env_id, env_config={"dynamics": dynamics})
        .env_runners(num_env_runners=0, rollout_fragment_length=1)
        .learners(num_learners=0)
        .training(
            train_batch_size_per_learner=256,
            num_steps_sampled_before_learning_starts=warmup,
            actor_lr=3e-4,
            critic_lr=3e-4,
            alpha_lr=3e-4,
            replay_buffer_config={"type": "EpisodeReplayBuffer", "capacity": max(steps, 1000)},
        )
        .reporting(min_sample_timesteps_per_iteration=max(1, min(1000, steps)))
        .debugging(seed=seed, log_level="ERROR")
    )


MUJOCO_PPO_TRAINING = {
    "num_epochs": 10,
    "lr": 3e-4,
    "gamma": 0.99,
    "lambda_": 0.95,
    "clip_param": 0.2,
    "vf_clip_param": 1e4,  # RLlib's default 10 would cap the value loss at MuJoCo's returns
    "entropy_coeff": 0.0,
}
"""PPO's usual MuJoCo settings (CleanRL/SB3), besides batch and minibatch sizes."""
MUJOCO_PPO_MODEL = {"fcnet_hiddens": [64, 64], "fcnet_activation": "tanh", "vf_share_layers": False}
"""64x64 tanh policy and a separate value net."""


def ppo_config(env_id: str, dynamics: str, steps: int, seed: int) -> Any:
    """A MuJoCo PPO config (local sampling, 4 vector envs, 2048-step batches, 64x64 tanh nets,
    separate value net; the usual MuJoCo settings) for `steps` env steps."""
    from ray.rllib.algorithms.ppo import PPOConfig

    batch = max(64, min(2048, steps))
    return (
        PPOConfig()
        .environment(env_id, env_config={"dynamics": dynamics})
        .env_runners(num_env_runners=0, num_envs_per_env_runner=4)
        .learners(num_learners=0)
        .training(
            train_batch_size_per_learner=batch, minibatch_size=min(64, batch), **MUJOCO_PPO_TRAINING
        )
        .rl_module(model_config=dict(MUJOCO_PPO_MODEL))
        .debugging(seed=seed, log_level="ERROR")
    )


_CONFIGS = {"ppo": ppo_config, "sac": sac_config}


def trainer_config(trainer: str, env_id: str, dynamics: str, steps: int, seed: int) -> Any:
    """The algorithm config `collect` trains with (`TRAINERS`)."""
    _check_choices("trainer", [trainer], TRAINERS)
    return _CONFIGS[trainer](env_id, dynamics, steps, seed)


def train_policy(
    trainer: str, env_id: str, dynamics: str, steps: int, seed: int = 0, log: Any = print
) -> TrainRun:
    """Train `trainer` for about `steps` env steps; snapshot the policy after every iteration."""
    t0 = time.perf_counter()
    algo = trainer_config(trainer, env_id, dynamics, steps, seed).build_algo()
    snapshots: list[PolicySnapshot] = []
    try:
        sampled = 0
        while sampled < steps:
            result = algo.train()
            runners = result.get("env_runners", {})
            sampled = int(runners.get("num_env_steps_sampled_lifetime", sampled + 1))
            ret = float(runners.get("episode_return_mean", float("nan")))
            buffer = getattr(algo, "local_replay_buffer", None)
            snapshots.append(
                PolicySnapshot(
                    env_steps=sampled,
                    train_return=ret,
                    num_replay_episodes=len(buffer.episodes) if buffer is not None else 0,
                    state=copy.deepcopy(algo.get_module().get_state()),
                )
            )
            log(f"  {trainer} {dynamics}: {sampled} steps, train return {ret:.1f}")
        replay = list(algo.local_replay_buffer.episodes) if trainer == "sac" else None
    finally:
        algo.stop()
    return TrainRun(snapshots, replay, time.perf_counter() - t0)


def _runner(trainer: str, env_id: str, dynamics: str, seed: int) -> Any:
    """An RLlib SingleAgentEnvRunner with the trainer's module on the env under `dynamics`."""
    from ray.rllib.env.single_agent_env_runner import SingleAgentEnvRunner

    config = trainer_config(trainer, env_id, dynamics, 1000, seed).env_runners(
        num_envs_per_env_runner=1, batch_mode="complete_episodes"
    )
    return SingleAgentEnvRunner(config=config)


def sample_episodes(
    runner: Any, steps: int, *, random_actions: bool = False, explore: bool = True
) -> list[Any]:
    """Complete episodes from `runner` until at least `steps` env steps are collected.

    Actions are stored in the module's normalised space clipped to [-1, 1] (what the env
    ran): a Gaussian PPO policy samples outside it, which a tanh-squashed CQL policy cannot
    represent (its log-likelihood of such an action is undefined).
    """
    episodes: list[Any] = []
    total = 0
    while total < steps:
        for eps in runner.sample(num_episodes=1, random_actions=random_actions, explore=explore):
            if eps.is_done:
                actions = eps.actions.data
                if isinstance(actions, np.ndarray) and actions.dtype.kind == "f":
                    np.clip(actions, -1.0, 1.0, out=actions)
                episodes.append(eps)
                total += len(eps)
    return episodes


def return_stats(episodes: Sequence[Any]) -> dict[str, Any]:
    """Episode-return statistics of complete episodes (what the manifest stores)."""
    returns = np.array([float(e.get_return()) for e in episodes], dtype=np.float64)
    lengths = np.array([len(e) for e in episodes], dtype=np.int64)
    if returns.size == 0:
        raise ValueError("no complete episodes to compute return statistics from")
    return {
        "num_episodes": int(returns.size),
        "num_steps": int(lengths.sum()),
        "return_mean": float(returns.mean()),
        "return_std": float(returns.std()),
        "return_min": float(returns.min()),
        "return_max": float(returns.max()),
        "length_mean": float(lengths.mean()),
    }


def write_episodes(episodes: Sequence[Any], path: Path) -> None:
    """Write complete episodes as parquet rows in RLlib's episode format (msgpack_numpy)."""
    import msgpack
    import msgpack_numpy as mnp
    import ray

    rows = [{"item": msgpack.packb(e.get_state(), default=mnp.encode)} for e in episodes]
    ray.data.from_items(rows).repartition(1).write_parquet(path.as_posix())


def _save_policy(runner: Any, state: dict[str, Any], path: Path) -> None:
    runner.module.set_state(state)
    runner.module.save_to_path(path.as_posix())


def collect(
    env_id: str,
    out: str | os.PathLike[str],
    steps: int,
    *,
    dynamics: Sequence[str] = DYNAMICS,
    qualities: Sequence[str] = QUALITIES,
    train_steps: int = 200_000,
    trainer: str = "ppo",
    seed: int = 0,
    overwrite: bool = False,
    log: Any = print,
) -> Path:
    """Collect `steps` env steps per (dynamics, quality) under `out/<task>/`; return that dir.

    Policies are trained with `trainer` ("ppo" or "sac") for `train_steps` env steps per
    dynamics. `train_steps=0` skips training: medium/expert then use the untrained policy (for
    tests) and medium-replay is unavailable.
    """
    import ray

    import rllib_asor.envs  # noqa: F401  (registers the env ids)

    _check_choices("quality", qualities, QUALITIES)
    if steps < 1:
        raise ValueError(f"steps={steps!r} is invalid: allowed an integer >= 1")
    _check_choices("trainer", [trainer], TRAINERS)
    if train_steps < 0:
        raise ValueError(f"train_steps={train_steps!r} is invalid: allowed an integer >= 0")
    if train_steps == 0 and "medium-replay" in qualities:
        raise ValueError("quality 'medium-replay' needs training: set train_steps > 0")
    if not dynamics:
        raise ValueError("dynamics is empty: allowed one or more of " + ", ".join(DYNAMICS))
    if not ray.is_initialized():
        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)

    out = Path(out).resolve()  # RLModule.save_to_path wants an absolute path (a URI)
    task = task_name(env_id)
    final = out / task
    if final.exists() and not overwrite:
        raise ValueError(f"{final} exists; pass --overwrite to replace it")
    out.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{task}.tmp-", dir=out))
    t0 = time.perf_counter()
    try:
        manifest: dict[str, Any] = {
            "format": FORMAT,
            "task": task,
            "env": env_id,
            "created": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
            "command": " ".join(sys.argv) if sys.argv else "",
            "settings": {
                "steps": steps, "trainer": trainer, "train_steps": train_steps, "seed": seed
            },
            "datasets": {},
            "reference_returns": {},
            "policies": {},
        }
        for dyn in dynamics:
            manifest["datasets"][dyn], manifest["policies"][dyn] = _collect_dynamics(
                env_id, dyn, tmp / dyn, steps, qualities, trainer, train_steps, seed, log
            )
            stats = manifest["datasets"][dyn]
            refs = {q: stats[q]["return_mean"] for q in ("random", "expert") if q in stats}
            manifest["reference_returns"][dyn] = refs
        manifest["seconds"] = round(time.perf_counter() - t0, 1)
        (tmp / MANIFEST).write_text(json.dumps(manifest, indent=2) + "\n")
        if final.exists():
            trash = Path(tempfile.mkdtemp(prefix=f".{task}.old-", dir=out))
            os.replace(final, trash / task)
            os.replace(tmp, final)
            shutil.rmtree(trash, ignore_errors=True)
        else:
            os.replace(tmp, final)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    log(f"wrote {final} in {time.perf_counter() - t0:.0f} s")
    return final


TINY_STEPS = 200
"""Env steps per (dynamics, quality) of `tiny_datasets` (a smoke run's data, not for results)."""


def tiny_datasets(env_id: str, paths: Sequence[str], out: str | os.PathLike[str]) -> dict[str, str]:
    """Build small stand-ins for dataset dirs `.../<task>/<dynamics>/<quality>` under `out`.

    For `rllib train --test` on a fresh clone: TINY_STEPS env steps per (dynamics, quality)
    with an untrained policy (512 training steps when medium-replay is asked for). Returns
    {path: stand-in path}; paths not of that form are left out.
    """
    import ray

    wanted: dict[str, tuple[str, str]] = {}
    for path in paths:
        parts = Path(path).parts
        if len(parts) >= 3 and parts[-2] in DYNAMICS and parts[-1] in QUALITIES:
            wanted[path] = (parts[-2], parts[-1])
    if not wanted:
        return {}
    qualities = sorted({q for _, q in wanted.values()}, key=QUALITIES.index)
    dynamics = sorted({d for d, _ in wanted.values()}, key=DYNAMICS.index)
    started = not ray.is_initialized()
    try:
        root = collect(
            env_id,
            out,
            TINY_STEPS,
            dynamics=dynamics,
            qualities=qualities,
            train_steps=512 if "medium-replay" in qualities else 0,
            overwrite=True,
            log=lambda *_: None,
        )
    finally:
        if started:  # the caller sizes its own Ray
            ray.shutdown()
    return {path: str(root / d / q) for path, (d, q) in wanted.items()}


def _collect_dynamics(
    env_id: str,
    dyn: str,
    root: Path,
    steps: int,
    qualities: Sequence[str],
    trainer: str,
    train_steps: int,
    seed: int,
    log: Any,
) -> tuple[dict[str, Any], dict[str, Any]]:
    stats: dict[str, Any] = {}
    policies: dict[str, Any] = {}
    runner = _runner(trainer, env_id, dyn, seed)
    try:
        picked: dict[str, PolicySnapshot] = {}
        run = None
        if train_steps > 0 and set(qualities) & {"medium", "expert", "medium-replay"}:
            run = train_policy(trainer, env_id, dyn, train_steps, seed, log)
            picked = run.pick()
        else:
            untrained = PolicySnapshot(0, float("nan"), 0, runner.module.get_state())
            picked = {"medium": untrained, "expert": untrained}
        for name, snap in picked.items():
            _save_policy(runner, snap.state, root / "policies" / name)
            policies[name] = {
                "path": f"{dyn}/policies/{name}",
                "env_steps": snap.env_steps,
                "train_return": snap.train_return if math.isfinite(snap.train_return) else None,
                "trainer": trainer,
                "train_seconds": round(run.seconds, 1) if run is not None else 0.0,
            }
        for quality in qualities:
            if quality == "medium-replay":
                assert run is not None
                episodes = _replay_episodes(run, picked["medium"], runner, steps)
            else:
                if quality != "random":
                    runner.module.set_state(picked[quality].state)
                episodes = sample_episodes(runner, steps, random_actions=quality == "random")
            write_episodes(episodes, root / quality)
            stats[quality] = {"path": f"{dyn}/{quality}", **return_stats(episodes)}
            log(
                f"  {dyn}/{quality}: {stats[quality]['num_episodes']} episodes, "
                f"{stats[quality]['num_steps']} steps, return {stats[quality]['return_mean']:.1f}"
            )
    finally:
        runner.stop()
    return stats, policies


def _replay_episodes(run: TrainRun, medium: PolicySnapshot, runner: Any, steps: int) -> list[Any]:
    """medium-replay: what training saw up to the medium snapshot. SAC: its replay buffer's
    complete episodes (all of them if none is complete by then). PPO keeps no buffer: each
    snapshot up to medium re-samples an equal share of `steps` (the policies training ran)."""
    if run.replay_episodes is not None:
        cut = medium.num_replay_episodes
        episodes = [e for e in run.replay_episodes[:cut] if e.is_done]
        return episodes or [e for e in run.replay_episodes if e.is_done]
    upto = [s for s in run.snapshots if s.env_steps <= medium.env_steps] or [medium]
    episodes = []
    for snap in upto:
        runner.module.set_state(snap.state)
        episodes += sample_episodes(runner, max(1, steps // len(upto)))
    return episodes


def _check_choices(key: str, values: Iterable[str], allowed: Sequence[str]) -> None:
    for v in values:
        if v not in allowed:
            raise ValueError(f"{key}={v!r} is invalid: allowed {' | '.join(allowed)}")


# ------------------------------------------------------------------------------ loading
@dataclass(frozen=True)
class OfflineDataset:
    """A validated task directory: its manifest and the parquet dirs of the chosen parts."""

    root: Path
    manifest: dict[str, Any]
    paths: tuple[str, ...]
    dynamics: tuple[str, ...]
    qualities: tuple[str, ...]

    @property
    def env(self) -> str:
        return str(self.manifest["env"])

    @property
    def task(self) -> str:
        return str(self.manifest["task"])

    @property
    def num_steps(self) -> int:
        ds = self.manifest["datasets"]
        return sum(int(ds[d][q]["num_steps"]) for d in self.dynamics for q in self.qualities)


def read_manifest(root: str | os.PathLike[str]) -> dict[str, Any]:
    """The manifest of a task directory; ValueError naming the path if missing or invalid."""
    root = Path(root)
    if not root.is_dir():
        raise ValueError(f"offline dataset {root} does not exist or is not a directory; {_HINT}")
    file = root / MANIFEST
    if not file.is_file():
        raise ValueError(f"no {MANIFEST} in {root}; {_HINT}")
    try:
        manifest = json.loads(file.read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise ValueError(f"{file} is not valid JSON ({e}); {_HINT}") from None
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
        got = manifest.get("format") if isinstance(manifest, dict) else type(manifest).__name__
        raise ValueError(f"{file} has format {got!r}, expected {FORMAT!r}; {_HINT}")
    for key in ("task", "env", "datasets", "reference_returns"):
        if key not in manifest:
            raise ValueError(f"{file} lacks the key {key!r}; {_HINT}")
    return manifest


def load_dataset(
    path: str | os.PathLike[str],
    *,
    dynamics: str | Sequence[str] | None = None,
    quality: str | Sequence[str] | None = None,
) -> OfflineDataset:
    """Validate a dataset and select parts of it.

    `path` is a task dir (`data/offline/hopper`) or one part (`data/offline/hopper/original/
    medium`, which selects that part). `dynamics`/`quality` select parts (None: all present).
    """
    path = Path(path)
    root = path
    if not (path / MANIFEST).exists() and (path.parent.parent / MANIFEST).is_file():
        root = path.parent.parent
        if dynamics is None and quality is None:
            dynamics, quality = path.parent.name, path.name
    manifest = read_manifest(root)
    available = manifest["datasets"]
    dyns = _as_tuple(dynamics) or tuple(available)
    for d in dyns:
        if d not in available:
            raise ValueError(
                f"dynamics {d!r} not in {root}: allowed {' | '.join(available) or '(none)'}"
            )
    quals = _as_tuple(quality) or tuple(dict.fromkeys(q for d in dyns for q in available[d]))
    paths = []
    for d in dyns:
        for q in quals:
            if q not in available[d]:
                raise ValueError(
                    f"quality {q!r} not in {root}/{d}: allowed {' | '.join(available[d])}"
                )
            part = root / available[d][q]["path"]
            if not part.is_dir() or not any(part.glob("*.parquet")):
                raise ValueError(f"no parquet files in {part}; {_HINT}")
            paths.append(part.resolve().as_posix())
    return OfflineDataset(root.resolve(), manifest, tuple(paths), dyns, quals)


def _as_tuple(value: str | Sequence[str] | None) -> tuple[str, ...]:
    if value is None:
        return ()
    return (value,) if isinstance(value, str) else tuple(value)


def offline_input(
    config: Any,
    path: str | os.PathLike[str],
    *,
    dynamics: str | Sequence[str] | None = None,
    quality: str | Sequence[str] | None = None,
    **offline_data: Any,
) -> Any:
    """Point an offline RLlib config (CQL, BC, ...) at a dataset; returns the same config.

    Sets `config.environment(<the dataset's env>)` when no env is set (the spaces come from
    it) and `config.offline_data(input_=<parquet dirs>, input_read_episodes=True, ...)`;
    extra keyword arguments go to `offline_data` (e.g. `dataset_num_iters_per_learner`).
    """
    import rllib_asor.envs  # noqa: F401  (registers the env ids in this process)

    ds = load_dataset(path, dynamics=dynamics, quality=quality)
    if config.env is None:
        config.environment(ds.env)
    kwargs: dict[str, Any] = {"input_": list(ds.paths), "input_read_episodes": True}
    kwargs.update(offline_data)
    config.offline_data(**kwargs)
    return config


# ------------------------------------------------------------------------------ scores
def normalized_score(
    return_: float,
    task: str,
    manifest: Mapping[str, Any] | str | os.PathLike[str],
    dynamics: str = "original",
) -> float:
    """D4RL score 100·(R − R_random)/(R_expert − R_random), with the manifest's own random and
    expert mean returns under `dynamics`; `manifest` is a dict or a task directory."""
    if not isinstance(manifest, Mapping):
        manifest = read_manifest(manifest)
    if manifest.get("task") != task:
        raise ValueError(f"manifest is for task {manifest.get('task')!r}, not {task!r}")
    refs = manifest["reference_returns"].get(dynamics)
    if not refs or "random" not in refs or "expert" not in refs:
        raise ValueError(
            f"no random and expert reference returns for dynamics {dynamics!r} of task {task!r}"
        )
    lo, hi = float(refs["random"]), float(refs["expert"])
    if math.isclose(hi, lo):
        raise ValueError(
            f"expert and random returns of {task}/{dynamics} are equal ({lo}); cannot normalise"
        )
    return 100.0 * (float(return_) - lo) / (hi - lo)


def policy_module(algo_or_path: Any) -> Any:
    """The default policy's RLModule of an Algorithm, an RLModule, or a checkpoint path
    (an Algorithm checkpoint dir or an RLModule dir)."""
    from ray.rllib.core import DEFAULT_MODULE_ID
    from ray.rllib.core.rl_module.rl_module import RLModule

    if isinstance(algo_or_path, RLModule):
        return algo_or_path
    if isinstance(algo_or_path, str | os.PathLike):
        path = Path(algo_or_path)
        inner = path / "learner_group" / "learner" / "rl_module" / DEFAULT_MODULE_ID
        if inner.is_dir():
            path = inner
        if not path.is_dir():
            raise ValueError(
                f"checkpoint {path} does not exist; expected an Algorithm or RLModule checkpoint"
            )
        return RLModule.from_checkpoint(path.as_posix())
    learner = getattr(algo_or_path.learner_group, "_learner", None)
    if learner is not None:
        return learner.module[DEFAULT_MODULE_ID]
    module = algo_or_path.get_module(DEFAULT_MODULE_ID)
    if module is None:
        raise ValueError("the Algorithm has no local policy module; pass a checkpoint path")
    return module


def rollout_returns(
    module: Any, env_id: str, dynamics: str, episodes: int, seed: int = 0
) -> list[float]:
    """Undiscounted returns of `episodes` deterministic episodes of `module` on the env."""
    import gymnasium as gym
    import torch
    from ray.rllib.core.columns import Columns

    import rllib_asor.envs  # noqa: F401

    env = gym.make(env_id, dynamics=dynamics)
    low, high = env.action_space.low, env.action_space.high
    dist_cls = module.get_inference_action_dist_cls()
    returns = []
    try:
        for i in range(episodes):
            obs, _ = env.reset(seed=seed + i)
            done, total = False, 0.0
            while not done:
                with torch.no_grad():
                    out = module.forward_inference(
                        {Columns.OBS: torch.as_tensor(obs, dtype=torch.float32)[None]}
                    )
                    dist = dist_cls.from_logits(out[Columns.ACTION_DIST_INPUTS])
                    a = dist.to_deterministic().sample()[0].numpy()
                # SAC/CQL squash into [-1, 1]; map onto the env's bounds (RLlib's unsquash).
                a = np.clip(low + (a + 1.0) * (high - low) / 2.0, low, high)
                obs, r, term, trunc, _ = env.step(a)
                total += float(r)
                done = term or trunc
            returns.append(total)
    finally:
        env.close()
    return returns


def evaluate(
    algo_or_path: Any,
    manifest: Mapping[str, Any] | str | os.PathLike[str],
    *,
    dynamics: Sequence[str] | None = None,
    episodes: int = 5,
    seed: int = 0,
) -> dict[str, dict[str, float]]:
    """Run the policy under each dynamics (default: the manifest's); return per dynamics
    `return_mean`, `return_std` and `normalized_score`, plus `mean` over dynamics."""
    if not isinstance(manifest, Mapping):
        manifest = read_manifest(manifest)
    module = policy_module(algo_or_path)
    out: dict[str, dict[str, float]] = {}
    for dyn in dynamics or tuple(manifest["datasets"]):
        rets = rollout_returns(module, manifest["env"], dyn, episodes, seed)
        out[dyn] = {
            "return_mean": float(np.mean(rets)),
            "return_std": float(np.std(rets)),
            "normalized_score": normalized_score(
                float(np.mean(rets)), manifest["task"], manifest, dyn
            ),
        }
    if out:
        out["mean"] = {
            k: float(np.mean([v[k] for v in out.values()]))
            for k in ("return_mean", "normalized_score")
        }
    return out


# ------------------------------------------------------------------------------ command line
def main(argv: Sequence[str] | None = None) -> int:
    """`python -m rllib_asor.rllib.offline collect|info|evaluate ...`."""
    p = argparse.ArgumentParser(
        prog="python -m rllib_asor.rllib.offline", description=__doc__.split("\n")[0]
    )
    sub = p.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("collect", help="train a policy per dynamics and write the datasets")
    c.add_argument("--env", required=True, help="env id, e.g. rllib_asor/HopperShift-v0")
    c.add_argument("--out", default="data/offline", help="output root (default data/offline)")
    c.add_argument("--steps", type=int, required=True, help="env steps per (dynamics, quality)")
    c.add_argument("--dynamics", nargs="+", default=list(DYNAMICS), help="dynamics presets")
    c.add_argument("--qualities", nargs="+", default=list(QUALITIES), choices=QUALITIES)
    c.add_argument("--trainer", choices=TRAINERS, default="ppo", help="policy trainer (ppo)")
    c.add_argument(
        "--train-steps",
        "--sac-steps",
        dest="train_steps",
        type=int,
        default=200_000,
        help="trainer env steps per dynamics (0: untrained policy)",
    )
    c.add_argument("--seed", type=int, default=0)
    c.add_argument("--overwrite", action="store_true", help="replace an existing task dir")
    c.add_argument(
        "--torch-threads", type=int, default=1, help="torch intra-op threads (default 1)"
    )
    i = sub.add_parser("info", help="validate a dataset and print its return statistics")
    i.add_argument("path")
    e = sub.add_parser("evaluate", help="normalised scores of a checkpoint under each dynamics")
    e.add_argument("checkpoint")
    e.add_argument("--data", required=True, help="the task dir, e.g. data/offline/hopper")
    e.add_argument("--episodes", type=int, default=5)
    args = p.parse_args(argv)
    logging.getLogger("ray.data").setLevel(logging.WARNING)  # one progress log per write
    try:
        if args.cmd == "collect":
            import torch

            # Measured on 2 shared cores: OpenMP threads spinning under load made SAC ~10x slower.
            torch.set_num_threads(args.torch_threads)
            collect(
                args.env, args.out, args.steps, dynamics=args.dynamics, qualities=args.qualities,
                train_steps=args.train_steps, trainer=args.trainer, seed=args.seed,
                overwrite=args.overwrite,
            )  # fmt: skip
        elif args.cmd == "info":
            ds = load_dataset(args.path)
            print(json.dumps({"env": ds.env, "datasets": ds.manifest["datasets"],
                              "reference_returns": ds.manifest["reference_returns"]}, indent=2))  # fmt: skip
        else:
            print(
                json.dumps(evaluate(args.checkpoint, args.data, episodes=args.episodes), indent=2)
            )
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
