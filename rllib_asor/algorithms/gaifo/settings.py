"""`GaifoSettings`: GAIfO's own settings (the YAML `gaifo:` block, `GaifoConfig.gaifo(...)`).

A bad value raises ValueError naming the key, the value and what is allowed.
"""

from __future__ import annotations

from typing import Annotated, ClassVar

from pydantic import Field

from rllib_asor.settings_model import (
    Allowed,
    BlockSettings,
    IntAtLeast1,
    NonNegative,
    Positive,
    one_of,
)

GRAD_PENALTY_FORMS = ("zero_centred", "one_centred_mix")
"""`grad_penalty_form`'s values (`TransitionDiscriminator.gradient_penalty`)."""
INPUT_NORM_ROWS = ("expert", "round")
"""`input_norm_rows`' values (`GaifoTrainer.update`)."""


class GaifoSettings(BlockSettings):
    """GAIfO's settings."""

    block: ClassVar[str] = "gaifo"
    label: ClassVar[str] = "a GAIfO"

    demonstrations: Annotated[
        str | None, Allowed("a path: an .npz of state-only demonstrations or a dataset dir")
    ] = None
    """State-only expert transitions (`rllib_asor.algorithms.common.demonstrations`)."""
    disc_hiddens: Annotated[
        tuple[Annotated[int, Field(ge=1)], ...],
        Field(min_length=1, strict=False),
        Allowed("a non-empty list of positive ints"),
    ] = (64, 64)
    """The discriminator's hidden ReLU layers."""
    disc_lr: Positive = 1e-3
    """Adam lr of the discriminator."""
    disc_steps: IntAtLeast1 = 5
    """Discriminator gradient steps per training iteration."""
    disc_batch_size: IntAtLeast1 = 256
    """Policy transitions per discriminator step (as many expert ones)."""
    grad_penalty: NonNegative = 0.0
    """Weight of the discriminator's gradient penalty (0: none); its form `grad_penalty_form`."""
    grad_penalty_form: one_of(GRAD_PENALTY_FORMS) = "zero_centred"
    """`zero_centred`: E‖∇ logit‖² at expert inputs; `one_centred_mix`: E(‖∇ logit‖ − 1)² at
    mixtures α·expert + (1 − α)·policy rows, α ~ N(0, 1) per element (the GARAT authors'
    `compute_grad_pen`, weight 10 there). Gradients w.r.t. the normalised input."""
    input_norm: bool = True
    """Normalise the discriminator's inputs by a mean and std (`input_norm_rows`)."""
    input_norm_rows: one_of(INPUT_NORM_ROWS) = "expert"
    """Whose mean and std: `expert`, the expert rows', fixed; `round`, at every discriminator
    update the expert rows' and that update's policy rows' together (over all Learners), as
    the GARAT authors normalise each round's target and grounded rows."""
    reward_form: one_of(("gail", "airl")) = "gail"
    """gail: −log(1 − D(s, s′)); airl: log D − log(1 − D) (the logit)."""
    reward_scale: NonNegative = 1.0
    """Factor on the discriminator's reward."""
    env_reward_weight: NonNegative = 0.0
    """Factor on the env's reward added to it (0: pure imitation, as the paper)."""
    state_dims: Annotated[
        Annotated[int, Field(ge=1)] | None, Allowed("null or an int ≥ 1")
    ] = None
    """The discriminator reads the first `state_dims` observation features (None: all)."""
    disc_input: one_of(("s_next", "obs_next", "obs_delta")) = "s_next"
    """What D reads of a transition (o, o′), s the first `state_dims` features of o: `s_next`
    (s, s′); `obs_next` (o, s′), the whole observation then s′ (GARAT's (s, a, s′) on its
    grounding MDP, whose observation is (s, a)); `obs_delta` (o, s′ − s). With `obs_*` the
    demonstrations carry the whole observation."""
    disc_on_batch: bool = True
    """Train D on each training batch's policy rows (`disc_steps` steps, after their rewards are
    written); false: D is trained only from outside (`GaifoTrainer.update`; GARAT's
    `disc_data: deterministic`)."""
    seed: int = 0
    """Seed of the expert-row sampling."""
