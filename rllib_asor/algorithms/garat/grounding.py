"""GARAT's grounding step: the action transformer trained as GAIfO's policy on `GroundingEnv`.

A local GAIfO run (PPO, no extra actors) whose discriminator reads the source-state part of the
grounding MDP's observation (`state_dims`) and scores (s, s′) against the target's
transitions; the GAIL reward −log(1 − D) is the transformer's only reward, as in the authors'
`ATPEnv.step`. Returns the transformer (its module spec and weights) and the last statistics.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from ray.rllib.core.rl_module.rl_module import RLModuleSpec

from rllib_asor.algorithms.garat.envs import GroundingEnv, SavedTransformer, make_source
from rllib_asor.algorithms.garat.settings import GaratSettings


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
    from rllib_asor.algorithms.gaifo.config import GaifoConfig

    s = settings
    source = make_source({"env": env, "env_config": env_config})
    try:
        state_dims = int(np.prod(source.observation_space.shape))
    finally:
        source.close()
    batch = s.grounding_batch_size
    config = (
        GaifoConfig()
        .environment(
            GroundingEnv,
            env_config={
                "env": env,
                "env_config": dict(env_config or {}),
                "action_tf_ratio": s.action_tf_ratio,
                "seed": s.seed,
                "behaviour": behaviour,
            },
        )
        .env_runners(num_env_runners=0, num_envs_per_env_runner=1)
        .environment(normalize_actions=False, clip_actions=True)
        .learners(num_learners=0)
        .training(
            lr=s.transformer_lr,
            gamma=0.99,
            train_batch_size=batch,
            minibatch_size=min(256, batch),
            num_epochs=5,
            entropy_coeff=0.0,
        )
        .rl_module(model_config={"fcnet_hiddens": list(s.transformer_hiddens)})
        .gaifo(
            demonstrations=demonstrations,
            state_dims=state_dims,
            disc_hiddens=s.disc_hiddens,
            disc_lr=s.disc_lr,
            disc_steps=s.disc_steps,
            grad_penalty=s.grad_penalty,
            seed=s.seed,
        )
        .debugging(seed=s.seed)
        .reporting(metrics_num_episodes_for_smoothing=5)
    )
    algo = config.build_algo()
    try:
        stats: dict[str, float] = {}
        for _ in range(s.grounding_iterations):
            result = algo.train()
            stats = {
                f"grounding_{k}": float(v)
                for k, v in (result.get("learners", {}).get("gaifo") or {}).items()
            }
        module = algo.get_module()
        saved = SavedTransformer(
            RLModuleSpec(
                module_class=type(module),
                observation_space=module.observation_space,
                action_space=module.action_space,
                model_config=module.model_config,
            ),
            module.get_state(inference_only=False),
        )
    finally:
        algo.stop()
    return saved, stats
