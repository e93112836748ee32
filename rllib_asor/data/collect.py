"""Collecting offline datasets: train a policy per dynamics, sample episodes, write a task dir.

Policies are trained per dynamics with PPO (default; ~10x cheaper per env step than RLlib's SAC
on a small CPU machine) or SAC, and snapshotted after every iteration; `random` uses uniform
actions, `medium`/`expert` the picked snapshots, `medium-replay` what training saw up to the
medium snapshot (format.py describes the layout). A task directory is written into a temporary
sibling and renamed when complete, so a crash leaves no half-written dataset behind.
"""

from __future__ import annotations

import copy
import datetime as _dt
import json
import math
import os
import shutil
import sys
import tempfile
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rllib_asor.data.format import (
    DYNAMICS,
    FORMAT,
    MANIFEST,
    QUALITIES,
    return_stats,
    task_name,
    write_episodes,
)

POLICY_QUALITIES = ("medium", "expert")
TRAINERS = ("ppo", "sac")


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


MUJOCO_SAC_TRAINING = {
    "gamma": 0.99,
    "lr": None,
    "actor_lr": 3e-4,
    "critic_lr": 3e-4,
    "alpha_lr": 3e-4,
    "tau": 0.005,
    "twin_q": True,
    "initial_alpha": 1.0,
    "n_step": 1,
    "train_batch_size_per_learner": 256,
}
"""SAC's usual MuJoCo settings (the SAC paper, SB3, CleanRL): batch 256, lr 3e-4, τ 0.005."""
MUJOCO_SAC_MODEL = {"fcnet_hiddens": [256, 256], "fcnet_activation": "relu"}
"""256x256 ReLU networks."""

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
        # "local": a `ray start` cluster on this machine would refuse num_cpus (as the CLI does)
        ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False)

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
                "steps": steps,
                "trainer": trainer,
                "train_steps": train_steps,
                "seed": seed,
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
