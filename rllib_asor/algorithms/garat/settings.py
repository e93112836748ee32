"""`GaratSettings`: GARAT's own settings (the YAML `garat:` block, `GaratConfig.garat(...)`).

Defaults follow the authors' scripts (`Ricky-Zhu/GARAT train_garat.sh`, `reinforcedgat.py`)
where they have one: `ACTION_TF_RATIO = 2`, `--disc_lr 3e-3`, `--atp_lr 3e-4`, `--loss_function
GAIL`, GroundedEnv's `alpha = 1`. A bad value raises ValueError naming the key, the value and
what is allowed.
"""

from __future__ import annotations

from typing import Annotated, Any, ClassVar

from pydantic import Field, model_validator

from rllib_asor.algorithms.gaifo.settings import GRAD_PENALTY_FORMS
from rllib_asor.settings_model import (
    Allowed,
    BlockSettings,
    IntAtLeast0,
    IntAtLeast1,
    NonNegative,
    Positive,
    one_of,
)


class GaratSettings(BlockSettings):
    """GARAT's settings."""

    block: ClassVar[str] = "garat"
    label: ClassVar[str] = "a GARAT"

    demonstrations: Annotated[
        str | None, Allowed("a path: an .npz of state-only target transitions or a dataset dir")
    ] = None
    """The target's transitions, recorded by the behaviour policy (`behaviour_policy`)."""
    behaviour_policy: Annotated[
        str | None, Allowed("null or a checkpoint path (an Algorithm's or an RLModule's)")
    ] = None
    """The grounding's behaviour policy: a checkpoint whose deterministic action plays a_t, as
    the authors' initial policy π₀ (the target data must be its rollouts in the target); None:
    uniformly random actions (the target data recorded with random actions)."""
    target_env_config: Annotated[
        dict[str, Any] | None, Allowed("null or a mapping (the target env's env_config)")
    ] = None
    """env_config of the target env (the evaluation env); None: evaluate in the source."""
    grounding_iterations: IntAtLeast1 = 20
    """PPO iterations of the action transformer (GAIfO on the grounding MDP)."""
    grounding_batch_size: IntAtLeast1 = 2000
    """Grounding-MDP steps per grounding iteration."""
    transformer_hiddens: Annotated[
        tuple[Annotated[int, Field(ge=1)], ...],
        Field(min_length=1, strict=False),
        Allowed("a non-empty list of positive ints"),
    ] = (64, 64)
    """Hidden layers of the transformer's policy and value networks."""
    transformer_lr: Positive = 3e-4
    """Adam lr of the transformer's PPO (`--atp_lr`)."""
    transformer_epochs: IntAtLeast1 = 5
    """PPO epochs over each transformer batch (`--noptepochs`; 1 in `train_garat.sh`)."""
    transformer_clip_param: Positive = 0.3
    """PPO's clip range for the transformer (RLlib's default; `--clip_range 0.1` in
    `train_garat.sh`)."""
    transformer_entropy_coeff: NonNegative = 0.0
    """PPO's entropy bonus for the transformer (`--ent_coeff 0.01` in `train_garat.sh`)."""
    transformer_gamma: Annotated[float, Field(ge=0, le=1), Allowed("a number in [0, 1]")] = 0.99
    """The transformer's PPO discount (GAE λ stays RLlib's 1.0; stable-baselines' PPO2 default
    0.99 in the authors' runs). 0 makes each step's advantage its own reward less the value of
    (s, a): D scores single transitions, and a return over the episode's later steps adds their
    noise to every step's signal."""
    transformer_init_std: Annotated[
        float | None, Field(gt=0), Allowed("null or a number > 0")
    ] = None
    """None: RLlib's default policy head, whose network outputs log σ (σ ≈ 1 at the start);
    a number: a state-independent log σ (stable-baselines' PPO2 `MlpPolicy`, the authors')
    that starts at this σ. PPO moves the mean by a share of σ per iteration, so σ sets how
    finely the transformer's Δ can settle."""
    generator_iterations: IntAtLeast1 = 1
    """With `disc_data: deterministic`: the transformer's PPO iterations per discriminator
    update, D fixed in between (the authors train it for `--generator_epochs` × `--gsim_trans`
    = 250,000 steps per D update: `trainer.py`, `train_action_transformer_policy`)."""
    action_tf_ratio: Positive = 2.0
    """|Δ| ≤ ratio · half the action range (`ACTION_TF_RATIO`)."""
    alpha: NonNegative = 1.0
    """The grounded env plays clip(a + alpha·Δ(s, a)) (GroundedEnv's `alpha`)."""
    disc_hiddens: Annotated[
        tuple[Annotated[int, Field(ge=1)], ...],
        Field(min_length=1, strict=False),
        Allowed("a non-empty list of positive ints"),
    ] = (64, 64)
    """The discriminator's hidden ReLU layers."""
    disc_lr: Positive = 3e-3
    """Adam lr of the discriminator (`--disc_lr`)."""
    disc_steps: IntAtLeast1 = 5
    """Discriminator gradient steps per grounding iteration."""
    disc_warmup_iterations: IntAtLeast0 = 0
    """The first grounding iterations in which D takes 5 × `disc_steps` steps (the authors'
    warm-up: `trainer.py`, 5 × `--noptepochs` epochs while the GAN iteration is ≤ 10)."""
    disc_input: one_of(("s_next", "s_a_next", "s_a_delta")) = "s_next"
    """What the discriminator reads of a transition: `s_next` (s, s′); `s_a_next` (s, a, s′),
    a the behaviour policy's action (before the transformer), the authors' input
    (`reinforcedgat.py`: `concat_sas`); `s_a_delta` (s, a, s′ − s), the same information with
    the change of the state, which a small dynamics change moves by a larger share of its
    spread. `s_a_*` need `behaviour_policy` (the target rows' a is π₀(s)). Inputs are
    normalised as `disc_norm` says."""
    disc_norm: one_of(("target", "round")) = "target"
    """Whose mean and std normalise D's inputs: `target`, the target rows', fixed; `round`, at
    every discriminator update the target rows' and that update's grounded rows' together (the
    authors' per-round normalisation)."""
    disc_data: one_of(("rollouts", "deterministic")) = "rollouts"
    """The grounded rows D trains on: `rollouts`, the transformer's PPO batch (Δ sampled);
    `deterministic`, before each grounding iteration `grounding_batch_size` fresh steps of the
    grounding MDP with the transformer's deterministic Δ, D fixed during the PPO update (the
    authors' `train_discriminator`: `GroundedEnv(use_deterministic=True)`)."""
    grad_penalty: NonNegative = 1.0
    """Weight of the discriminator's gradient penalty (`--compute_grad_penalty`; 0: none)."""
    grad_penalty_form: one_of(GRAD_PENALTY_FORMS) = "zero_centred"
    """GAIfO's `grad_penalty_form`: `zero_centred`, E‖∇ logit‖² at target inputs;
    `one_centred_mix`, the authors' form (`rl_gat/gat.py` `compute_grad_pen`, weight 10):
    E(‖∇ logit‖ − 1)² at mixtures α·target + (1 − α)·grounded rows, α ~ N(0, 1) per element."""
    seed: int = 0
    """Seed of the grounding run (its env, behaviour actions and networks)."""

    @model_validator(mode="after")
    def _generator_iterations_need_a_fixed_d(self) -> GaratSettings:
        if self.generator_iterations > 1 and self.disc_data != "deterministic":
            raise ValueError(
                f"garat.generator_iterations={self.generator_iterations!r} is not allowed with "
                f"garat.disc_data={self.disc_data!r} (D trains on every PPO batch there); "
                "expected 1, or disc_data: deterministic"
            )
        return self
