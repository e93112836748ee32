"""State-only expert demonstrations for the imitation-from-observation baselines (BCO, SOIL,
GAIfO, GARAT): one format, how to read it, write it and make it.

A `Demonstrations` holds expert transitions (s_t, s_{t+1}) with no actions. Sources
(`load_demonstrations`):

- an ``.npz`` file with the arrays ``obs``, ``next_obs``, ``episode_ids``, ``terminateds``
  (what `save_demonstrations` writes; other arrays, e.g. ``actions``, are ignored);
- a dataset written by `rllib data collect`: a task dir (``data/offline/hopper``: the
  ``expert`` level of every dynamics in it) or one part (``data/offline/hopper/original/
  expert``); actions in it are ignored.

`demonstrations_from_episodes` turns episodes (RLlib `SingleAgentEpisode`s or
``(observations [T+1, ...], terminated)`` pairs) into one; `rollout_demonstrations` rolls a
trained checkpoint, RLModule or any ``obs -> action`` function out on an env into one.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

ARRAYS = ("obs", "next_obs", "episode_ids", "terminateds")
"""The arrays of the ``.npz`` format, in order."""
ALLOWED = (
    "allowed: an .npz file with the arrays obs, next_obs, episode_ids, terminateds "
    "(save_demonstrations), or a dataset task dir or part dir written by `rllib data collect`"
)


@dataclass(frozen=True)
class Demonstrations:
    """State-only expert data: N transitions (s_t, s_{t+1}), their episode and end flag."""

    obs: np.ndarray
    """[N, *obs_shape] float32: s_t."""
    next_obs: np.ndarray
    """[N, *obs_shape] float32: s_{t+1}."""
    episode_ids: np.ndarray
    """[N] int64: the episode each transition belongs to."""
    terminateds: np.ndarray
    """[N] bool: s_{t+1} is terminal (not merely the end of a truncated episode)."""

    def __post_init__(self) -> None:
        n = len(self.obs)
        if self.next_obs.shape != self.obs.shape:
            raise ValueError(
                f"demonstrations: next_obs has shape {self.next_obs.shape}, obs {self.obs.shape}; "
                "allowed: the same shape"
            )
        for name in ("episode_ids", "terminateds"):
            arr = getattr(self, name)
            if arr.shape != (n,):
                raise ValueError(
                    f"demonstrations: {name} has shape {arr.shape}; allowed: ({n},), one per row"
                )

    def __len__(self) -> int:
        return len(self.obs)

    @property
    def obs_shape(self) -> tuple[int, ...]:
        return tuple(self.obs.shape[1:])

    @property
    def num_episodes(self) -> int:
        return int(np.unique(self.episode_ids).size)

    @classmethod
    def of(cls, obs: Any, next_obs: Any, episode_ids: Any, terminateds: Any) -> Demonstrations:
        """Build one from array-likes, cast to the format's dtypes."""
        return cls(
            np.asarray(obs, dtype=np.float32),
            np.asarray(next_obs, dtype=np.float32),
            np.asarray(episode_ids, dtype=np.int64).reshape(-1),
            np.asarray(terminateds, dtype=bool).reshape(-1),
        )


def save_demonstrations(path: str | os.PathLike[str], demos: Demonstrations) -> None:
    """Write `demos` as an ``.npz`` file at `path` (atomically: a temporary file in the same
    directory renamed over `path`)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            np.savez(f, **{name: getattr(demos, name) for name in ARRAYS})
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp's 0600 -> what open() would have made
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def load_demonstrations(path: str | os.PathLike[str], observation_space: Any) -> Demonstrations:
    """Read demonstrations from `path` (an ``.npz`` file or a `rllib data collect` dataset, see
    the module docstring) and check them against `observation_space` (a gymnasium Box).

    Raises one ValueError naming the path and the problem (missing, unknown format, empty,
    wrong observation shape) and what is allowed.
    """
    p = Path(path)
    if not p.exists():
        hint = ""
        if "offline" in p.parts:
            hint = "; make the offline datasets first: `make datasets`"
        elif (p.parent / "make.py").is_file():
            hint = f"; write them first: `python {p.parent / 'make.py'}`"
        raise ValueError(f"demonstrations {p} do not exist{hint}; {ALLOWED}")
    if p.is_file() and p.suffix == ".npz":
        demos = _read_npz(p)
    elif p.is_dir():
        demos = _read_dataset(p)
    else:
        raise ValueError(f"demonstrations {p}: unknown format; {ALLOWED}")
    if len(demos) == 0:
        raise ValueError(f"demonstrations {p} are empty (0 transitions); allowed: at least one")
    want = tuple(getattr(observation_space, "shape", None) or ())
    if demos.obs_shape != want:
        raise ValueError(
            f"demonstrations {p} have the wrong observation shape: expected {want}, got "
            f"{demos.obs_shape}; allowed: demonstrations of this env (its observation space)"
        )
    return demos


def _read_npz(p: Path) -> Demonstrations:
    try:
        with np.load(p, allow_pickle=False) as f:
            missing = [name for name in ARRAYS if name not in f.files]
            if missing:
                raise ValueError(
                    f"demonstrations {p} lack the arrays {', '.join(missing)} "
                    f"(found: {', '.join(f.files) or 'none'}); {ALLOWED}"
                )
            arrays = {name: f[name] for name in ARRAYS}
    except ValueError as e:
        if str(e).startswith(f"demonstrations {p}"):
            raise
        raise ValueError(f"demonstrations {p}: unreadable .npz ({e}); {ALLOWED}") from None
    except (OSError, EOFError) as e:
        raise ValueError(f"demonstrations {p}: unreadable .npz ({e}); {ALLOWED}") from None
    try:
        return Demonstrations.of(**arrays)
    except ValueError as e:
        raise ValueError(f"demonstrations {p}: {str(e).removeprefix('demonstrations: ')}") from None


def _read_dataset(p: Path) -> Demonstrations:
    """The expert part(s) of a `rllib data collect` dataset, or one part dir of it."""
    from rllib_asor.data.format import MANIFEST, load_dataset

    if (p / MANIFEST).is_file():  # a task dir: its expert level, every dynamics
        try:
            parts = load_dataset(p, quality="expert").paths
        except ValueError as e:
            raise ValueError(f"demonstrations {p}: {e}") from None
    elif any(p.glob("*.parquet")):
        parts = (p.as_posix(),)
    else:
        raise ValueError(
            f"demonstrations {p}: a directory without {MANIFEST} or parquet files; {ALLOWED}"
        )
    from rllib_asor.algorithms.maple.data import read_part

    episodes = []
    for part in parts:
        episodes += [(obs, terminated) for obs, _, _, terminated in read_part(part)]
    return demonstrations_from_episodes(episodes)


def demonstrations_from_episodes(episodes: Iterable[Any]) -> Demonstrations:
    """Demonstrations from episodes: RLlib `SingleAgentEpisode`s (actions ignored) or
    ``(observations [T+1, ...], terminated)`` pairs; episodes with no step are skipped. Episode
    ids are 0, 1, ... in order; only an episode's last transition can be terminal."""
    obs, nxt, ids, terms = [], [], [], []
    for i, ep in enumerate(episodes):
        if isinstance(ep, tuple):
            o, terminated = ep
        else:
            o, terminated = ep.get_observations(), ep.is_terminated
        o = np.asarray(o, dtype=np.float32)
        t = len(o) - 1
        if t < 1:
            continue
        obs.append(o[:-1])
        nxt.append(o[1:])
        ids.append(np.full(t, i, dtype=np.int64))
        term = np.zeros(t, dtype=bool)
        term[-1] = bool(terminated)
        terms.append(term)
    if not obs:
        return Demonstrations.of(np.zeros((0,)), np.zeros((0,)), [], [])
    return Demonstrations.of(
        np.concatenate(obs), np.concatenate(nxt), np.concatenate(ids), np.concatenate(terms)
    )


def rollout_demonstrations(
    policy: Any,
    env: str | Any,
    episodes: int,
    *,
    seed: int = 0,
    env_kwargs: Mapping[str, Any] | None = None,
    explore: bool = False,
    action_fn: Callable[[Any], Any] | None = None,
) -> Demonstrations:
    """Roll `policy` out for `episodes` episodes (reset seeds seed, seed + 1, ...) into
    demonstrations.

    `policy`: a checkpoint path (an Algorithm's or an RLModule's), an RLModule, an Algorithm
    (its deterministic action, or a sample with `explore`), or a function ``obs -> action``.
    `env`: a gymnasium id (made with `env_kwargs`) or an env. `action_fn(action_space)` maps
    the policy's actions onto the env (default: ``int`` for Discrete, clipping to the Box
    otherwise, as RLlib's env runner does for PPO; pass `rllib_asor.evaluation.rollout.unsquash`
    for SAC/CQL modules).
    """
    import gymnasium as gym

    from rllib_asor.evaluation import rollout as loop

    if episodes < 1:
        raise ValueError(f"episodes={episodes!r} is invalid: allowed an integer >= 1")
    if (
        callable(policy)
        and not hasattr(policy, "forward_inference")
        and not hasattr(policy, "learner_group")
    ):
        act = policy
    else:
        batch = loop.module_policy(loop.policy_module(policy), explore)
        act = lambda o: batch(loop.stack_obs([o]))[0]  # noqa: E731
    made = isinstance(env, str)
    if made:  # our env ids are registered: importing any rllib_asor module registers them
        env = gym.make(env, **dict(env_kwargs or {}))
    if action_fn is None:
        action_fn = loop.to_int if isinstance(env.action_space, gym.spaces.Discrete) else loop.clip
    to_env = action_fn(env.action_space)
    trajectories = []
    try:
        for i in range(episodes):
            o, _ = env.reset(seed=seed + i)
            seen, done, terminated = [o], False, False
            while not done:
                o, _, terminated, truncated, _ = env.step(to_env(act(o)))
                seen.append(o)
                done = terminated or truncated
            trajectories.append((np.stack(seen), terminated))
    finally:
        if made:
            env.close()
    return demonstrations_from_episodes(trajectories)


def resolve_path(path: str | os.PathLike[str]) -> str:
    """`path`, or relative to the directory Tune started in (trials run in their own)."""
    path = os.fspath(path)
    if os.path.isabs(path) or os.path.exists(path):
        return path
    start = os.environ.get("TUNE_ORIG_WORKING_DIR")
    return os.path.join(start, path) if start else path
