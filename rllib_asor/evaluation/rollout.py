"""The project's one episode loop, and the policies it runs.

`play(envs, seeds, policy)` steps a batch of envs together, each to the end of one episode
(reset with its seed), and returns an `Episode` per env; `watch(i, action, reward, info)` sees
every step. `rollout(actor, env, episodes)` runs episodes one at a time on one env (reset seeds
seed, seed + 1, ...) through it: the offline scorer, MAPLE, ESCP and the MuJoCo, lava and
traffic studies. The race's evaluation (`rllib_asor.race.evaluation`) steps all its courses in
one `play`.

What differs per algorithm is the actor, a fresh `Step` per episode: `module_actor` (any
RLModule: its deterministic action, or a sampled one; observations optionally transformed,
e.g. by a frozen MeanStdFilter), ESCP's inference window (`algorithms/escp/evaluate.py`),
MAPLE's GRU context (`algorithms/maple/evaluation.py`). `action_fn(space)` maps the policy's
action onto the env's (`unsquash` for SAC/CQL, `clip` as RLlib's env runner does for PPO).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rllib_asor import ray_compat as compat

Transform = Callable[[Any], Any]
Step = Callable[[Any, Mapping[str, Any]], Any]
"""One episode's policy: `step(obs, info) -> action`; it may keep state across the episode."""
Actor = Callable[[], Step]
"""A fresh `Step` for each episode (zeroed windows, hidden states, ...)."""
BatchPolicy = Callable[[list[Any], list[Mapping[str, Any]]], Sequence[Any]]
"""`policy(observations, infos) -> one action per env`, for the envs still running, in order."""
Watch = Callable[[int, Any, float, Mapping[str, Any]], None]
"""`watch(env index, action, reward, info)` after every step."""


@dataclass
class Episode:
    """One finished episode: undiscounted return, length, how it ended, its last info."""

    total_reward: float = 0.0
    length: int = 0
    terminated: bool = False
    info: Mapping[str, Any] = field(default_factory=dict)


def play(
    envs: Sequence[Any],
    seeds: Sequence[int],
    policy: BatchPolicy,
    *,
    to_env: Transform | None = None,
    watch: Watch | None = None,
    options: Mapping[str, Any] | None = None,
) -> list[Episode]:
    """Run one episode on each env (reset with its seed and `options`), all stepped together;
    `to_env` maps the policy's actions onto the env's."""
    obs, infos = [], []
    for env, seed in zip(envs, seeds, strict=True):
        o, info = env.reset(seed=seed, options=options)
        obs.append(o)
        infos.append(info)
    episodes = [Episode() for _ in envs]
    live = list(range(len(envs)))
    while live:
        actions = policy([obs[i] for i in live], [infos[i] for i in live])
        running = []
        for i, action in zip(live, actions, strict=True):
            obs[i], r, term, trunc, infos[i] = envs[i].step(
                action if to_env is None else to_env(action)
            )
            ep = episodes[i]
            ep.total_reward, ep.length = ep.total_reward + float(r), ep.length + 1
            if watch is not None:
                watch(i, action, float(r), infos[i])
            if term or trunc:
                ep.terminated, ep.info = bool(term), infos[i]
            else:
                running.append(i)
        live = running
    return episodes


@dataclass
class Rollouts:
    """Per episode of a `rollout`: return, length, and the `Episode` itself."""

    returns: list[float] = field(default_factory=list)
    lengths: list[int] = field(default_factory=list)
    episodes: list[Episode] = field(default_factory=list)


def rollout(
    actor: Actor,
    env: str | Any,
    episodes: int,
    *,
    seed: int = 0,
    env_kwargs: Mapping[str, Any] | None = None,
    action_fn: Callable[[Any], Transform] | None = None,
    watch: Watch | None = None,
    reset_options: Mapping[str, Any] | None = None,
) -> Rollouts:
    """`episodes` episodes of `actor` (a fresh step per episode; reset seeds seed, seed + 1,
    ..., and `reset_options`) on `env`: a gymnasium id (made with `env_kwargs`, closed at the
    end) or an env. `action_fn(env.action_space)` maps actions onto the env; `watch(episode,
    action, reward, info)` sees every step."""
    import gymnasium as gym  # our ids are registered when rllib_asor is imported

    made = isinstance(env, str)
    if made:
        env = gym.make(env, **dict(env_kwargs or {}))
    to_env = None if action_fn is None else action_fn(env.action_space)
    out = Rollouts()
    try:
        for i in range(episodes):
            seen = None if watch is None else (lambda _, a, r, info, i=i: watch(i, a, r, info))
            (ep,) = play(
                [env], [seed + i], _one_env(actor()), to_env=to_env, watch=seen,
                options=reset_options,
            )  # fmt: skip
            out.returns.append(ep.total_reward)
            out.lengths.append(ep.length)
            out.episodes.append(ep)
    finally:
        if made:
            env.close()
    return out


def _one_env(step: Step) -> BatchPolicy:
    """A one-episode step as the batch policy of one env."""
    return lambda obs, infos: [step(obs[0], infos[0])]


# ---------------------------------------------------------------------- action maps
def unsquash(space: Any) -> Transform:
    """[-1, 1] → the Box's [low, high], clipped (RLlib's unsquash of SAC/CQL actions)."""
    low, high = space.low, space.high
    return lambda a: np.clip(low + (a + 1.0) * (high - low) / 2.0, low, high)


def clip(space: Any) -> Transform:
    """Clipped to the Box's [low, high] (what RLlib's env runner does with PPO's actions)."""
    low, high = space.low, space.high
    return lambda a: np.clip(a, low, high)


def to_int(space: Any) -> Transform:
    """A Discrete space's action as a Python int."""
    return int


# ---------------------------------------------------------------------- RLModule policies
def deterministic_sample(dist: Any) -> Any:
    """The distribution's mode as an action. For RLlib's squashed Gaussian (SAC, CQL) that is
    the squashed mean tanh(μ): RLlib 2.60's `TorchSquashedGaussian.to_deterministic()` returns μ
    *before* the tanh (the env runner then clips it), an action the policy never samples."""
    from ray.rllib.core.distribution.torch.torch_distribution import TorchSquashedGaussian

    if isinstance(dist, TorchSquashedGaussian):
        return compat.squash(dist, dist.loc)
    return dist.to_deterministic().sample()


def stack_obs(observations: Sequence[Any]) -> Any:
    """Observations of several envs as one batch (dict observations key by key)."""
    first = observations[0]
    if isinstance(first, Mapping):
        return {k: np.stack([o[k] for o in observations]) for k in first}
    return np.stack(observations)


def module_policy(module: Any, explore: bool = False) -> Callable[[Any, Any], np.ndarray]:
    """`policy(obs_batch, infos) -> actions` of an RLModule on a stacked batch (`stack_obs`;
    float observations as float32): its mode (`deterministic_sample`), or with `explore` a
    sample of its exploration distribution."""
    import torch
    from ray.rllib.core import Columns

    from rllib_asor.devices import module_device

    dist_cls = (
        module.get_exploration_action_dist_cls()
        if explore
        else module.get_inference_action_dist_cls()
    )
    forward = module.forward_exploration if explore else module.forward_inference

    def tensor(x: Any, device: Any) -> Any:
        if isinstance(x, Mapping):
            return {k: tensor(v, device) for k, v in x.items()}
        t = torch.as_tensor(x, device=device)
        return t.float() if t.is_floating_point() else t

    def act(batch: Any, infos: Any = None) -> np.ndarray:
        with torch.no_grad():
            logits = forward({Columns.OBS: tensor(batch, module_device(module))})
            dist = dist_cls.from_logits(logits[Columns.ACTION_DIST_INPUTS])
            return (dist.sample() if explore else deterministic_sample(dist)).cpu().numpy()

    return act


def deterministic_action(module: Any, obs: Any) -> np.ndarray:
    """The module's deterministic action for one observation."""
    return module_policy(module)(stack_obs([obs]))[0]


def module_actor(module: Any, obs_fn: Transform | None = None, explore: bool = False) -> Actor:
    """An RLModule as a `rollout` actor: its action for each observation (through `obs_fn`)."""
    act = module_policy(module, explore)

    def step(obs: Any, info: Mapping[str, Any]) -> Any:
        return act(stack_obs([obs if obs_fn is None else obs_fn(obs)]))[0]

    return lambda: step


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
        if not path.exists():
            raise ValueError(
                f"checkpoint {path} does not exist; expected an Algorithm or RLModule checkpoint"
            )
        return RLModule.from_checkpoint(path.as_posix())
    learner = compat.local_learner(algo_or_path.learner_group)
    if learner is not None:
        return learner.module[DEFAULT_MODULE_ID]
    module = algo_or_path.get_module(DEFAULT_MODULE_ID)
    if module is None:
        raise ValueError("the Algorithm has no local policy module; pass a checkpoint path")
    return module
