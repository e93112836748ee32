"""`BcoSettings`: BCO's own settings (the YAML `bco:` block, `BcoConfig.bco(...)`).

A bad value raises ValueError naming the key, the value and what is allowed.
"""

from __future__ import annotations

from typing import Annotated, ClassVar

from pydantic import Field

from rllib_asor.settings_model import Allowed, BlockSettings, IntAtLeast1, NonNegative, Positive


class BcoSettings(BlockSettings):
    """BCO's settings."""

    block: ClassVar[str] = "bco"
    label: ClassVar[str] = "a BCO"

    demonstrations: Annotated[
        str | None, Allowed("a path: an .npz of state-only demonstrations or a dataset dir")
    ] = None
    """State-only expert transitions (`rllib_asor.algorithms.common.demonstrations`)."""
    alpha: NonNegative = 0.0
    """BCO(α): env steps with the policy per later iteration, as a fraction of
    `pre_demo_steps` (0: BCO(0), no interaction after the first iteration). Online only."""
    pre_demo_steps: IntAtLeast1 = 5000
    """|I^pre|: env steps with random actions in the first iteration. Online only."""
    idm_hiddens: Annotated[
        tuple[Annotated[int, Field(ge=1)], ...],
        Field(min_length=1, strict=False),
        Allowed("a non-empty list of positive ints"),
    ] = (64, 64)
    """The inverse dynamics model's hidden tanh layers."""
    idm_lr: Positive = 1e-3
    """Adam lr of the inverse dynamics model."""
    idm_steps: IntAtLeast1 = 1000
    """Its Adam steps after each batch of new transitions (offline: once, on the dataset)."""
    idm_batch_size: IntAtLeast1 = 64
    """Transitions per step of the inverse dynamics model."""
    idm_capacity: IntAtLeast1 = 1_000_000
    """The newest transitions its buffer keeps."""
    bc_epochs: IntAtLeast1 = 10
    """Passes of behavioural cloning over the relabelled demonstrations per iteration
    (minibatches of `train_batch_size_per_learner`, Adam with the config's `lr`)."""
    evaluation_interval: Annotated[int, Field(ge=0), Allowed("an int ≥ 0")] = 10
    """Offline: evaluate the policy under the data's dynamics every this many iterations
    (`evaluation/...`; 0: never). Online runs report the env runners' returns."""
    evaluation_episodes: IntAtLeast1 = 5
    """Offline: episodes per dynamics of that evaluation."""
    seed: int = 0
    """Seed of the model's initial weights and its minibatches."""
