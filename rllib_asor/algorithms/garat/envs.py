"""GARAT's two envs around a source env (a gymnasium id and its kwargs).

- `GroundingEnv` (the authors' `ATPEnv`): the action transformer's MDP. Observation (s_t, a_t)
  with a_t the behaviour policy's action (a checkpoint's deterministic action, the authors' π₀,
  or uniformly random actions, see docs/baselines.md), action
  Δ_t in ±`action_tf_ratio`·half the action range, the source stepped with clip(a_t + Δ_t).
  Its reward is 0: GAIfO's piece writes the discriminator's.
- `GroundedEnv` (the authors' `GroundedEnv`): the source env whose actions a become
  clip(a + alpha·Δ(s, a)), Δ the transformer's deterministic action.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np


def make_source(config: dict[str, Any]) -> gym.Env:
    """The source env: `gym.make(config["env"], **config["env_config"])` (importing
    `rllib_asor` registered our env ids)."""
    return gym.make(config["env"], **dict(config.get("env_config") or {}))


def _box(space: gym.Space, what: str) -> gym.spaces.Box:
    if not isinstance(space, gym.spaces.Box) or len(space.shape) != 1:
        raise ValueError(f"GARAT needs a flat Box {what} space, got {space}; allowed: Box (D,)")
    return space


def behaviour_policy(path: str) -> Any:
    """obs -> the deterministic action of the policy saved at `path` (an Algorithm's or an
    RLModule's checkpoint), as RLlib's env runner plays a PPO action (clipped later)."""
    from rllib_asor.evaluation.rollout import module_policy, policy_module, stack_obs

    act = module_policy(policy_module(path), False)
    return lambda obs: np.asarray(act(stack_obs([obs]), None)[0], np.float32).reshape(-1)


class GroundingEnv(gym.Env):
    """The action transformer's MDP (module docstring). `config`: env, env_config,
    action_tf_ratio, seed, behaviour (a checkpoint path or a function obs -> action; None:
    uniformly random actions)."""

    def __init__(self, config: dict[str, Any] | None = None) -> None:
        config = dict(config or {})
        self.source = make_source(config)
        obs = _box(self.source.observation_space, "observation")
        act = _box(self.source.action_space, "action")
        self.low, self.high = act.low.astype(np.float32), act.high.astype(np.float32)
        self.observation_space = gym.spaces.Box(
            np.concatenate([obs.low, self.low]).astype(np.float32),
            np.concatenate([obs.high, self.high]).astype(np.float32),
        )
        max_delta = (self.high - self.low) / 2 * float(config.get("action_tf_ratio", 2.0))
        self.action_space = gym.spaces.Box(-max_delta, max_delta, dtype=np.float32)
        self._rng = np.random.default_rng(config.get("seed", 0))
        behaviour = config.get("behaviour")  # a checkpoint path, or (Python) obs -> action
        self._policy = (
            behaviour if callable(behaviour) else behaviour_policy(behaviour) if behaviour else None
        )
        self._s: np.ndarray | None = None
        self._a: np.ndarray | None = None

    def _behaviour(self) -> np.ndarray:
        if self._policy is not None:
            return np.clip(self._policy(self._s), self.low, self.high).astype(np.float32)
        return self._rng.uniform(self.low, self.high).astype(np.float32)

    def _obs(self) -> np.ndarray:
        return np.concatenate([self._s, self._a]).astype(np.float32)

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> Any:
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        self._s, info = self.source.reset(seed=seed, options=options)
        self._a = self._behaviour()
        return self._obs(), info

    def step(self, action: Any) -> Any:
        played = np.clip(self._a + np.asarray(action, np.float32), self.low, self.high)
        self._s, _, terminated, truncated, info = self.source.step(played)
        self._a = self._behaviour()
        return self._obs(), 0.0, terminated, truncated, info

    def close(self) -> None:
        self.source.close()


class SavedTransformer:
    """The transformer's RLModule spec and weights, kept in the config (pickled with it into
    checkpoints and env runners); its repr is one line, so results and logs that print the
    config (Tune's result.json) do not carry the weights."""

    def __init__(self, spec: Any, state: dict[str, Any]) -> None:
        self.spec, self.state = spec, state

    def __getitem__(self, key: str) -> Any:
        return {"spec": self.spec, "state": self.state}[key]

    def __repr__(self) -> str:
        n = sum(int(np.size(v)) for v in self.state.values())
        return f"SavedTransformer({n} weights)"


class Transformer:
    """Δ(s, a): the deterministic action (the mean) of the transformer's RLModule, clipped to
    its action space. Built from a `SavedTransformer` (or `{"spec": ..., "state": ...}`)."""

    def __init__(self, saved: Any) -> None:
        self.module = saved["spec"].build()
        self.module.set_state(saved["state"])
        self.module.eval()
        space = self.module.action_space
        self.low, self.high, self.dim = space.low, space.high, int(space.shape[0])

    def delta(self, obs: np.ndarray, action: np.ndarray) -> np.ndarray:
        import torch
        from ray.rllib.core.columns import Columns

        from rllib_asor.devices import module_device

        x = torch.as_tensor(
            np.concatenate([obs, action]), dtype=torch.float32, device=module_device(self.module)
        )[None]
        with torch.no_grad():
            out = self.module.forward_inference({Columns.OBS: x})[Columns.ACTION_DIST_INPUTS]
        return np.clip(out[0, : self.dim].cpu().numpy(), self.low, self.high)


class GroundedEnv(gym.Wrapper):
    """The source env with the transformer (module docstring). `config`: env, env_config,
    transformer (None: the source itself), alpha."""

    def __init__(self, config: dict[str, Any] | None = None) -> None:
        config = dict(config or {})
        super().__init__(make_source(config))
        act = _box(self.env.action_space, "action")
        self.low, self.high = act.low, act.high
        saved = config.get("transformer")
        self.transformer = Transformer(saved) if saved is not None else None
        self.alpha = float(config.get("alpha", 1.0))
        self.source_config = dict(config.get("env_config") or {})
        self._s: np.ndarray | None = None

    def reset(self, **kwargs: Any) -> Any:
        self._s, info = self.env.reset(**kwargs)
        return self._s, info

    def step(self, action: Any) -> Any:
        a = np.clip(np.asarray(action, np.float32), self.low, self.high)
        if self.transformer is not None:
            a = np.clip(a + self.alpha * self.transformer.delta(self._s, a), self.low, self.high)
        self._s, reward, terminated, truncated, info = self.env.step(a)
        return self._s, reward, terminated, truncated, info
