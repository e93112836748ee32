"""GARAT's schedule of the two players: the discriminator's warm-up, the transformer's PPO
iterations per discriminator update (D fixed in between) and its PPO settings, on a real
grounding run on Pendulum; and their validation."""

from __future__ import annotations

import numpy as np
import pytest

from rllib_asor.algorithms.common.demonstrations import Demonstrations, save_demonstrations
from rllib_asor.algorithms.gaifo.trainer import GaifoTrainer
from rllib_asor.algorithms.garat import grounding
from rllib_asor.algorithms.garat.settings import GaratSettings


def test_several_generator_iterations_need_a_fixed_discriminator():
    with pytest.raises(ValueError, match=r"garat.generator_iterations=2 is not allowed with "
                       r"garat.disc_data='rollouts'.*expected 1, or disc_data: deterministic"):  # fmt: skip
        GaratSettings(generator_iterations=2)
    assert GaratSettings(generator_iterations=2, disc_data="deterministic").generator_iterations == 2
    with pytest.raises(ValueError, match=r"garat.disc_warmup_iterations=-1 is not allowed; "
                       "expected an int ≥ 0"):  # fmt: skip
        GaratSettings(disc_warmup_iterations=-1)
    defaults = GaratSettings()  # what every run before these settings did
    assert (defaults.generator_iterations, defaults.disc_warmup_iterations) == (1, 0)
    assert (defaults.transformer_epochs, defaults.transformer_clip_param) == (5, 0.3)
    assert (defaults.transformer_entropy_coeff, defaults.transformer_gamma) == (0.0, 0.99)
    with pytest.raises(ValueError, match=r"garat.transformer_gamma=1.5 is not allowed; "
                       r"expected a number in \[0, 1\]"):  # fmt: skip
        GaratSettings(transformer_gamma=1.5)


def test_warm_up_and_generator_iterations_schedule_the_two_players(tmp_path, monkeypatch):
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(40, 3)).astype(np.float32)
    path = tmp_path / "target.npz"
    save_demonstrations(path, Demonstrations.of(obs[:-1], obs[1:], [0] * 39, [False] * 39))
    d_steps, algos = [], []
    real_update, real_saved = GaifoTrainer.update, grounding.saved_transformer

    def counting_update(self, features):
        d_steps.append(len(d_steps))
        return real_update(self, features)

    def keep_algo(algo):
        algos.append(algo)
        return real_saved(algo)

    monkeypatch.setattr(GaifoTrainer, "update", counting_update)
    monkeypatch.setattr(grounding, "saved_transformer", keep_algo)
    settings = GaratSettings(
        grounding_iterations=3, grounding_batch_size=32, disc_steps=1, disc_data="deterministic",
        disc_warmup_iterations=1, generator_iterations=2, transformer_epochs=1,
        transformer_clip_param=0.1, transformer_entropy_coeff=0.01, transformer_gamma=0.0,
    )  # fmt: skip
    saved, _ = grounding.ground("Pendulum-v1", {}, settings, str(path))
    assert not any(k.endswith("log_std") for k in saved.state)  # no init std: σ from the network
    algo = algos[-1]
    assert algo.iteration == 3 * 2  # two PPO iterations per discriminator update
    assert len(d_steps) == 5 + 1 + 1  # 5 updates in the warm-up iteration, then 1 each
    assert (algo.config.num_epochs, algo.config.clip_param) == (1, 0.1)
    assert (algo.config.entropy_coeff, algo.config.gamma) == (0.01, 0.0)


def test_transformer_init_std_starts_a_free_log_std_there(tmp_path):
    with pytest.raises(ValueError, match=r"garat.transformer_init_std=0.0 is not allowed; "
                       "expected null or a number > 0"):  # fmt: skip
        GaratSettings(transformer_init_std=0.0)
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(40, 3)).astype(np.float32)
    path = tmp_path / "target.npz"
    save_demonstrations(path, Demonstrations.of(obs[:-1], obs[1:], [0] * 39, [False] * 39))
    settings = GaratSettings(
        grounding_iterations=1, grounding_batch_size=32, disc_steps=1, transformer_epochs=1,
        transformer_init_std=0.1,
    )  # fmt: skip
    saved, _ = grounding.ground("Pendulum-v1", {}, settings, str(path))
    (log_std,) = [v for k, v in saved.state.items() if k.endswith("log_std")]
    # one PPO update (one epoch of 32 rows at lr 3e-4) moves it by far less than log 10
    assert np.allclose(np.exp(log_std), 0.1, rtol=0.01)
