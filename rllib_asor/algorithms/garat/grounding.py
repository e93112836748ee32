"""GARAT's grounding step: the action transformer trained as GAIfO's policy on `GroundingEnv`.

A local GAIfO run (PPO, no extra actors) whose discriminator scores the grounding MDP's
transitions against the target's: (s, s′), the source-state part of its observation
(`state_dims`), or with `disc_input: s_a_*` (s, a, s′) / (s, a, s′ − s), a the behaviour
action in the observation (s, a), the target rows' a = π₀(s) (`with_behaviour_actions`, as the
authors' target data carry π₀'s actions). The GAIL reward −log(1 − D) is the transformer's
only reward, as in the authors' `ATPEnv.step`. D trains on the transformer's PPO batch, or with
`disc_data: deterministic` (the authors' `train_discriminator`) on fresh steps with its
deterministic Δ before each iteration (`deterministic_rows`, `train_discriminator`). Returns
the transformer (its module spec and weights) and the last statistics.
"""

from __future__ import annotations

import math
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from ray.rllib.core.rl_module.rl_module import RLModuleSpec

from rllib_asor.algorithms.common.demonstrations import (
    Demonstrations,
    load_demonstrations,
    save_demonstrations,
)
from rllib_asor.algorithms.garat.envs import (
    GroundingEnv,
    SavedTransformer,
    Transformer,
    behaviour_policy,
    make_source,
)
from rllib_asor.algorithms.garat.settings import GaratSettings

GAIFO_INPUT = {"s_next": "s_next", "s_a_next": "obs_next", "s_a_delta": "obs_delta"}
"""`GaratSettings.disc_input` -> `GaifoSettings.disc_input` on the grounding MDP."""


def check_disc_input(settings: GaratSettings, behaviour: object) -> None:
    """ValueError when `disc_input` needs the behaviour policy's actions and there is none."""
    if settings.disc_input != "s_next" and behaviour is None:
        raise ValueError(
            f"garat.disc_input={settings.disc_input!r} needs garat.behaviour_policy (the target "
            "rows' action a = π₀(s)); allowed: s_next with random behaviour actions, or "
            "s_a_next | s_a_delta with a behaviour policy"
        )


def with_behaviour_actions(
    demos: Demonstrations, policy: Callable[[np.ndarray], np.ndarray], space: gym.spaces.Box
) -> Demonstrations:
    """`demos` with observations (s, a): a = clip(policy(s)) to `space` (as `GroundingEnv`
    plays it), for s_t and s_{t+1}."""

    def add(obs: np.ndarray) -> np.ndarray:
        acts = [np.clip(policy(o), space.low, space.high).reshape(-1) for o in obs]
        return np.concatenate([obs.reshape(len(obs), -1), np.asarray(acts)], axis=1)

    return Demonstrations.of(
        add(demos.obs), add(demos.next_obs), demos.episode_ids, demos.terminateds
    )


def ground(
    env: str,
    env_config: dict[str, Any] | None,
    settings: GaratSettings,
    demonstrations: str,
    behaviour: str | Callable[[np.ndarray], np.ndarray] | None = None,
) -> tuple[SavedTransformer, dict[str, float]]:
    """Train the transformer on the source `env` (with `env_config`) against the target's
    `demonstrations` (`behaviour`: the behaviour policy's checkpoint or a function obs -> action,
    None: random actions);
    returns (the transformer, statistics of the last iteration)."""
    s = settings
    check_disc_input(s, behaviour)
    source = make_source({"env": env, "env_config": env_config})
    try:
        state_dims = int(np.prod(source.observation_space.shape))
        obs_space, act_space = source.observation_space, source.action_space
    finally:
        source.close()
    with tempfile.TemporaryDirectory(prefix="garat-") as tmp:
        if s.disc_input != "s_next":
            policy = behaviour if callable(behaviour) else behaviour_policy(str(behaviour))
            demos = load_demonstrations(demonstrations, obs_space)
            demonstrations = str(Path(tmp) / "target-with-actions.npz")
            save_demonstrations(demonstrations, with_behaviour_actions(demos, policy, act_space))
        return _ground(env, env_config, s, demonstrations, behaviour, state_dims)


def gaifo_block(s: GaratSettings, demonstrations: str, state_dims: int) -> dict[str, Any]:
    """The `gaifo:` settings of the grounding run: GARAT's discriminator settings in GAIfO's
    names (the target rows are GAIfO's expert rows)."""
    return {
        "demonstrations": demonstrations,
        "state_dims": state_dims,
        "disc_input": GAIFO_INPUT[s.disc_input],
        "disc_on_batch": s.disc_data == "rollouts",
        "disc_hiddens": s.disc_hiddens,
        "disc_lr": s.disc_lr,
        "disc_steps": s.disc_steps,
        "grad_penalty": s.grad_penalty,
        "grad_penalty_form": s.grad_penalty_form,
        "input_norm_rows": "expert" if s.disc_norm == "target" else "round",
        "seed": s.seed,
    }


def _ground(
    env: str,
    env_config: dict[str, Any] | None,
    s: GaratSettings,
    demonstrations: str,
    behaviour: str | Callable[[np.ndarray], np.ndarray] | None,
    state_dims: int,
) -> tuple[SavedTransformer, dict[str, float]]:
    """The GAIfO run of `ground` on target rows at `demonstrations`."""
    from rllib_asor.algorithms.gaifo.config import GaifoConfig

    batch = s.grounding_batch_size
    grounding_config = {
        "env": env,
        "env_config": dict(env_config or {}),
        "action_tf_ratio": s.action_tf_ratio,
        "seed": s.seed,
        "behaviour": behaviour,
    }
    config = (
        GaifoConfig()
        .environment(GroundingEnv, env_config=grounding_config)
        .env_runners(num_env_runners=0, num_envs_per_env_runner=1)
        .environment(normalize_actions=False, clip_actions=True)
        .learners(num_learners=0)
        .training(
            lr=s.transformer_lr,
            gamma=s.transformer_gamma,
            train_batch_size=batch,
            minibatch_size=min(256, batch),
            num_epochs=s.transformer_epochs,
            clip_param=s.transformer_clip_param,
            entropy_coeff=s.transformer_entropy_coeff,
        )
        .rl_module(
            model_config={
                "fcnet_hiddens": list(s.transformer_hiddens),
                "free_log_std": s.transformer_init_std is not None,
            }
        )
        .gaifo(**gaifo_block(s, demonstrations, state_dims))
        .debugging(seed=s.seed)
        .reporting(metrics_num_episodes_for_smoothing=5)
    )
    algo = config.build_algo()
    if s.transformer_init_std is not None:
        set_initial_std(algo, s.transformer_init_std)
    grounding = GroundingEnv(grounding_config) if s.disc_data == "deterministic" else None
    try:
        stats: dict[str, float] = {}
        for i in range(s.grounding_iterations):
            if grounding is not None:
                obs, nxt = deterministic_rows(grounding, saved_transformer(algo), batch, s.seed, i)
                warm = i < s.disc_warmup_iterations
                stats = train_discriminator(algo, obs, nxt, 5 if warm else 1)
            for _ in range(s.generator_iterations):
                result = algo.train()
            if grounding is None:
                stats = {
                    f"grounding_{k}": float(v)
                    for k, v in (result.get("learners", {}).get("gaifo") or {}).items()
                }
        saved = saved_transformer(algo)
    finally:
        algo.stop()
        if grounding is not None:
            grounding.close()
    return saved, stats


def set_initial_std(algo: Any, std: float) -> None:
    """Set the transformer's free log σ (`free_log_std`) to log `std` on every Learner and
    sync the env runners."""

    def fill(learner: Any) -> None:
        import torch

        with torch.no_grad():
            for module in learner.module.values():
                for name, p in module.named_parameters():
                    if name.endswith("log_std"):
                        p.fill_(math.log(std))

    algo.learner_group.foreach_learner(fill)
    algo.env_runner_group.sync_weights(from_worker_or_learner_group=algo.learner_group)


def saved_transformer(algo: Any) -> SavedTransformer:
    """The transformer as it is now: its RLModule spec and weights."""
    module = algo.get_module()
    return SavedTransformer(
        RLModuleSpec(
            module_class=type(module),
            observation_space=module.observation_space,
            action_space=module.action_space,
            model_config=module.model_config,
        ),
        module.get_state(inference_only=False),
    )


def deterministic_rows(
    env: GroundingEnv, saved: SavedTransformer, n: int, seed: int = 0, round_: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """`n` transitions (o, o′) of the grounding MDP `env` with the transformer's deterministic Δ
    (episodes reset with seeds from `seed`, `round_` and the episode count)."""
    transformer = Transformer(saved)
    k = int(np.prod(env.source.observation_space.shape))
    obs_rows, next_rows, episode = [], [], 0
    o, _ = env.reset(seed=seed + 100_000 * (round_ + 1))
    while len(obs_rows) < n:
        o2, _, terminated, truncated, _ = env.step(transformer.delta(o[:k], o[k:]))
        obs_rows.append(o)
        next_rows.append(o2)
        o = o2
        if terminated or truncated:
            episode += 1
            o, _ = env.reset(seed=seed + 100_000 * (round_ + 1) + episode)
    return np.asarray(obs_rows, np.float32), np.asarray(next_rows, np.float32)


def train_discriminator(
    algo: Any, obs: np.ndarray, next_obs: np.ndarray, rounds: int = 1
) -> dict[str, float]:
    """`rounds` × `disc_steps` steps of the Learner's discriminator on the grounded rows (o, o′)
    against the target's; the last round's statistics as `grounding_*`."""

    def update(learner: Any) -> dict[str, float]:
        import torch

        trainer = learner.gaifo
        o = torch.as_tensor(obs, device=trainer.device)
        o2 = torch.as_tensor(next_obs, device=trainer.device)
        features = trainer.features(o, o2)
        for _ in range(rounds):
            stats = trainer.update(features)
        return {f"grounding_{k}": float(v) for k, v in stats.items()}

    return [r.get() for r in algo.learner_group.foreach_learner(update)][0]
