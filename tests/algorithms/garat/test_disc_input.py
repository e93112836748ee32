"""GARAT's `disc_input`: the target rows' behaviour actions, the discriminator's rows of each
input on hand-made transitions, and the setting's validation (all without training)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch

from rllib_asor.algorithms.common.demonstrations import Demonstrations, save_demonstrations
from rllib_asor.algorithms.gaifo.settings import GaifoSettings
from rllib_asor.algorithms.gaifo.trainer import GaifoTrainer
from rllib_asor.algorithms.garat.config import GaratConfig
from rllib_asor.algorithms.garat.grounding import GAIFO_INPUT, ground, with_behaviour_actions
from rllib_asor.algorithms.garat.settings import GaratSettings

DEVICE = torch.device("cpu")
SPACE = gym.spaces.Box(-2.0, 2.0, (1,), np.float32)


def _target() -> Demonstrations:
    """Two transitions of a 2-feature state: s = (1, 2) -> (3, 5), s = (0, -1) -> (0.5, -1)."""
    obs = np.array([[1.0, 2.0], [0.0, -1.0]])
    nxt = np.array([[3.0, 5.0], [0.5, -1.0]])
    return Demonstrations.of(obs, nxt, [0, 0], [False, False])


def _pi0(s: np.ndarray) -> np.ndarray:
    """a = s[0] + s[1], clipped by the caller to ±2."""
    return np.array([s[0] + s[1]], np.float32)


def test_target_rows_get_the_clipped_behaviour_action_of_s_and_of_s_next():
    d = with_behaviour_actions(_target(), _pi0, SPACE)
    # a(1, 2) = 3 -> 2 (clipped); a(0, -1) = -1; a(3, 5) = 8 -> 2; a(0.5, -1) = -0.5
    assert d.obs.tolist() == [[1.0, 2.0, 2.0], [0.0, -1.0, -1.0]]
    assert d.next_obs.tolist() == [[3.0, 5.0, 2.0], [0.5, -1.0, -0.5]]
    assert d.episode_ids.tolist() == [0, 0] and d.terminateds.tolist() == [False, False]


@pytest.mark.parametrize(
    ("disc_input", "rows"),
    [
        ("s_next", [[1.0, 2.0, 3.0, 5.0], [0.0, -1.0, 0.5, -1.0]]),  # (s, s′)
        ("s_a_next", [[1.0, 2.0, 2.0, 3.0, 5.0], [0.0, -1.0, -1.0, 0.5, -1.0]]),  # (s, a, s′)
        ("s_a_delta", [[1.0, 2.0, 2.0, 2.0, 3.0], [0.0, -1.0, -1.0, 0.5, 0.0]]),  # (s, a, s′ − s)
    ],
)
def test_discriminator_rows_of_each_input_on_the_grounding_mdps_observation(disc_input, rows):
    d = with_behaviour_actions(_target(), _pi0, SPACE)
    settings = GaifoSettings(
        demonstrations="unused", state_dims=2, disc_input=GAIFO_INPUT[disc_input]
    )
    trainer = GaifoTrainer(settings, d, DEVICE)
    assert trainer.expert.tolist() == rows  # the target rows D trains on
    # a policy row of the grounding MDP: observation (s, a), next observation (s′, a′)
    obs = torch.tensor([[1.0, 2.0, 2.0], [0.0, -1.0, -1.0]], device=DEVICE)
    nxt = torch.tensor([[3.0, 5.0, 7.0], [0.5, -1.0, 7.0]], device=DEVICE)
    assert trainer.features(obs, nxt).tolist() == rows  # a′ (7) is never read
    # the inputs are normalised by the target rows' mean and std
    x = torch.tensor(rows, device=DEVICE)
    mean, std = x.mean(0), x.std(0, unbiased=False).clamp_min(1e-4)
    assert torch.allclose(trainer.disc.normalize(x), ((x - mean) / std).clamp(-5, 5))


def test_disc_input_is_validated_naming_the_allowed_values(tmp_path):
    expected = "garat.disc_input='sas' is not allowed; expected s_next | s_a_next | s_a_delta"
    with pytest.raises(ValueError, match=expected):
        GaratSettings(disc_input="sas")
    with pytest.raises(ValueError, match=expected):
        GaratConfig().garat(disc_input="sas")
    assert GaratSettings().disc_input == "s_next"  # the default reads (s, s′), as before
    path = tmp_path / "target.npz"
    save_demonstrations(path, _target())
    needs = r"garat.disc_input='s_a_next' needs garat.behaviour_policy.*allowed: s_next"
    settings = GaratSettings(disc_input="s_a_next")
    with pytest.raises(ValueError, match=needs):  # before any grounding is built
        ground("Pendulum-v1", {}, settings, str(path), None)
    config = GaratConfig().environment("Pendulum-v1")
    obs = np.zeros((2, 3), np.float32)
    save_demonstrations(path, Demonstrations.of(obs, obs, [0, 0], [False, False]))
    with pytest.raises(ValueError, match=needs):
        config.garat(demonstrations=str(path), disc_input="s_a_next").validate()


def test_deterministic_rows_step_the_grounding_mdp_with_the_transformers_mean_delta():
    from rllib_asor.algorithms.garat.envs import GroundingEnv, SavedTransformer
    from rllib_asor.algorithms.garat.grounding import deterministic_rows
    from tests.algorithms.garat.test_garat import delta_one_transformer

    spec, module = delta_one_transformer()  # Δ = 1 (its mean; sampling would add ±1 more)
    env = GroundingEnv({"env": "Pendulum-v1", "env_config": {"g": 10.0},
                        "behaviour": lambda s: np.array([0.5], np.float32)})  # fmt: skip
    obs, nxt = deterministic_rows(env, SavedTransformer(spec, module.get_state()), 3, seed=7)
    ref = gym.make("Pendulum-v1", g=10.0)
    s, _ = ref.reset(seed=7 + 100_000)  # round 0's first episode
    for t in range(3):  # a = 0.5 from π₀, played 0.5 + 1 = 1.5
        assert np.allclose(obs[t], [*s, 0.5])
        s = ref.step(np.array([1.5], np.float32))[0]
        assert np.allclose(nxt[t], [*s, 0.5])


def test_disc_data_is_validated_naming_the_allowed_values():
    with pytest.raises(ValueError, match="garat.disc_data='x' is not allowed; expected rollouts "
                       r"\| deterministic"):  # fmt: skip
        GaratSettings(disc_data="x")
    assert GaratSettings().disc_data == "rollouts"
