"""`asor_update` and `bonus_for_rows` on hand-made batches: rows not ranked get the bonus the
update gives ranked rows; the archive's real set has the size the mode and proxy call for; the
random partition follows the rng; a batch without proxy inputs shows the proxy its features;
the missing-next-states warning only where potential shaping was asked for; a full archive
keeps the newest of equal-return episodes."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from rllib_asor.asor import update
from rllib_asor.asor.archive import StateArchive
from rllib_asor.asor.config import AsorConfig
from rllib_asor.asor.proxy import make_proxy
from rllib_asor.asor.update import AsorBatch, AsorState, asor_update, bonus_for_rows
from tests.asor.test_state_behaviour import DIM, episodes

SMALL = {"seed": 0, "disc_hiddens": [8], "rnd_hiddens": [8], "rnd_embedding_dim": 4}


def _build(cfg: AsorConfig, seed: int = 0) -> tuple[AsorState, torch.nn.Module | None]:
    torch.manual_seed(seed)
    state = AsorState(cfg, DIM)
    proxy = make_proxy(cfg, DIM, 2, seed=1) if cfg.needs_proxy else None
    return state, proxy


@pytest.mark.parametrize(
    "settings",
    [
        {},  # robust: archive, batch-normalised logit bonus, potential shaping
        {"bonus_norm": "running"},
        {"bonus_norm": "off", "reward_form": "gail", "shaping": "direct"},
        {"preset": "paper", "mode": "srpo"},
    ],
    ids=["robust", "running", "off-gail-direct", "paper"],
)
def test_rows_not_ranked_get_the_bonus_the_update_gave_the_ranked_rows(settings: dict) -> None:
    cfg = AsorConfig(**SMALL, lambda_=0.3, lambda_warmup=False, **settings)
    state, proxy = _build(cfg)
    batch = episodes(0)
    result = asor_update(cfg, state, proxy, batch, np.random.default_rng(0))
    assert result.lam > 0 and result.reward_delta.abs().sum() > 0
    before = {k: v.clone() for k, v in state.state_dict().items()}
    again = bonus_for_rows(
        cfg, state, result.lam, batch.features, batch.next_features, batch.terminateds, batch.gamma
    )
    assert torch.allclose(again, result.reward_delta, atol=1e-6)
    for key, value in state.state_dict().items():  # nothing is updated a second time
        assert torch.equal(value, before[key]), key


@pytest.mark.parametrize(
    ("mode", "proxy", "real"),
    [
        ("asor", "rnd", 6),  # ⌈0.25·⌈0.5·48⌉⌉: value, then count
        ("asor", "ensemble", 24),  # ⌈0.5·48⌉: the ensemble cannot count states without actions
        ("srpo", "rnd", 24),
        ("count", "rnd", 12),  # ⌈0.25·48⌉
        ("random", "rnd", 6),  # the size of asor's
    ],
)
def test_the_archives_real_set_has_the_size_of_the_mode(mode: str, proxy: str, real: int) -> None:
    cfg = AsorConfig(**SMALL, mode=mode, proxy=proxy, rho_value=0.5, rho_count=0.25)
    state, prox = _build(cfg)
    batch = episodes(0)  # 6 terminated episodes, 48 states: all archived, all drawn
    result = asor_update(cfg, state, prox, batch, np.random.default_rng(0))
    assert len(state.archive) == 48  # the discriminator's batch: the real set, then the batch
    assert int(result.disc_labels.sum()) == real and len(result.disc_labels) == real + 48


@pytest.mark.parametrize("source", ["archive", "batch"])
def test_the_random_partition_follows_the_rng(source: str) -> None:
    cfg = AsorConfig(**SMALL, mode="random", real_source=source, rho_value=0.5, rho_count=0.25)
    runs = []
    for _ in range(2):
        state, proxy = _build(cfg)
        result = asor_update(cfg, state, proxy, episodes(0), np.random.default_rng(3))
        runs.append(result.disc_features[result.disc_labels > 0.5])
    assert len(runs[0]) == 6 and torch.equal(runs[0], runs[1])


def test_a_batch_without_proxy_inputs_shows_the_proxy_its_features() -> None:
    cfg = AsorConfig(**SMALL, preset="paper", mode="asor", proxy="rnd")
    batch = episodes(0)
    bare = AsorBatch(batch.features, batch.env_rewards, batch.values, gamma=batch.gamma)
    with_inputs = AsorBatch(
        batch.features, batch.env_rewards, batch.values, gamma=batch.gamma,
        proxy_inputs=update.ProxyInputs(batch.features),
    )
    got = [asor_update(cfg, *_build(cfg), b, np.random.default_rng(0)) for b in (bare, with_inputs)]
    assert torch.equal(got[0].disc_labels, got[1].disc_labels)
    assert torch.equal(got[0].reward_delta, got[1].reward_delta)


def test_the_missing_next_states_warning_only_when_potential_shaping_was_asked(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    warnings: list[str] = []
    monkeypatch.setattr(update, "_warn_once", warnings.append)
    batch = episodes(0)
    bare = AsorBatch(batch.features, batch.env_rewards, batch.values, gamma=batch.gamma)
    for shaping in ("direct", "potential"):
        cfg = AsorConfig(**SMALL, preset="paper", mode="srpo", shaping=shaping)
        result = asor_update(cfg, *_build(cfg), bare, np.random.default_rng(0))
        assert result.metrics["potential"] == 0.0
    assert len(warnings) == 1 and "no next states" in warnings[0]


def test_a_full_archive_keeps_the_newest_of_many_equal_return_episodes() -> None:
    arch = StateArchive(feature_dim=1, capacity=40, buckets=1)
    for i in range(30):  # 120 states of equal return: enough for an unstable sort to mix them
        arch.insert(torch.full((4, 1), float(i)), torch.zeros(4), 1.0, dynamics_id=0)
    kept = sorted({int(v) for v in arch.features[0, :40, 0].tolist()})
    assert kept == list(range(20, 30))


def test_the_reward_delta_has_the_dtype_of_the_env_rewards() -> None:
    cfg = AsorConfig(**SMALL, preset="paper", mode="srpo", lambda_=0.3)
    batch = episodes(0)
    wide = AsorBatch(batch.features, batch.env_rewards.double(), batch.values, gamma=batch.gamma)
    result = asor_update(cfg, *_build(cfg), wide, np.random.default_rng(0))
    assert result.reward_delta.dtype == torch.float64 and result.reward_delta.abs().sum() > 0
