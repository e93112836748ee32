"""What the ASOR update reports and the small pieces it is built from, on hand-set inputs
(each test aims at behaviour a mutation run showed untested).

- the update's diagnostics (`_metrics`): every value, which keys appear for all-real,
  all-generated and mixed batches;
- the critic's explained variance against the chunks' bootstrapped discounted returns;
- `explained_variance`, `scheduled_lambda`, `reward_bonus`'s forms, the normaliser at zero
  variance, the batch normaliser of the bonus;
- `flatten` of a MultiDiscrete with a 2-D `nvec` and of a Tuple with the wrong number of parts;
- `_top_k`'s documented tie-break; `concat_batches` over three batches.
"""

from __future__ import annotations

import logging
import math
import uuid
from types import SimpleNamespace

import gymnasium as gym
import numpy as np
import pytest
import torch

from rllib_asor.asor import update
from rllib_asor.asor.networks import RunningMeanStd, flatten
from rllib_asor.asor.partition import _top_k
from rllib_asor.asor.proxy import ProxyInputs
from rllib_asor.asor.reward import explained_variance, reward_bonus, scheduled_lambda
from rllib_asor.asor.update import AsorBatch, Chunk, concat_batches


# --- the update's diagnostics -----------------------------------------------------------------
def _metrics(real, archive=None, labels=(1.0, 0.0, 0.0, 0.0)):
    logits = torch.tensor([0.0, math.log(3.0), -math.log(3.0), 0.0])  # ω = 1/2, 3/4, 1/4, 1/2
    batch = SimpleNamespace(
        env_rewards=torch.tensor([1.0, 2.0, 3.0, 6.0]), values=torch.tensor([10.0, 20.0, 30.0, 40.0])
    )
    return update._metrics(
        SimpleNamespace(archive=archive),
        0.25,
        2.0,
        torch.tensor([-1.0, -2.0, 0.0, -1.0]),  # bonus
        torch.tensor([-3.0, 1.0, 2.0, 4.0]),  # delta
        logits,
        batch,
        torch.tensor(real),
        torch.tensor(labels),
    )


def test_metrics_report_every_value_of_a_mixed_batch():
    m = _metrics([True, True, False, False], archive=[0] * 7)
    expected = {
        "lambda": 0.25,
        "reward_scale": 2.0,
        "real_fraction": 0.25,
        "aug_reward_mean": 1.0,
        "aug_reward_min": -3.0,
        "aug_reward_max": 4.0,
        "aug_reward_abs_mean": 2.5,
        "bonus_mean": -1.0,
        "env_reward_mean": 3.0,
        "value_mean": 25.0,
        "omega_batch_mean": 0.5,
        "omega_real_mean": 0.625,
        "value_real_mean": 15.0,
        "omega_generated_mean": 0.375,
        "archive_states": 7.0,
    }
    assert m.keys() == expected.keys()
    for key, value in expected.items():
        assert m[key] == pytest.approx(value, abs=1e-6), key


def test_metrics_leave_out_the_side_a_batch_lacks_and_report_nothing_for_no_rows():
    all_real = _metrics([True, True, True, True])
    assert "omega_generated_mean" not in all_real and "archive_states" not in all_real
    assert all_real["omega_real_mean"] == pytest.approx(0.5)
    assert all_real["value_real_mean"] == pytest.approx(25.0)
    none_real = _metrics([False, False, False, False])
    assert "omega_real_mean" not in none_real and "value_real_mean" not in none_real
    assert none_real["omega_generated_mean"] == pytest.approx(0.5)
    assert _metrics([True, False, True, False], labels=())["real_fraction"] == 0.0
    empty = torch.zeros(0)
    batch = SimpleNamespace(env_rewards=empty, values=empty)
    state = SimpleNamespace(archive=None)
    assert update._metrics(state, 0.1, 1.0, empty, empty, empty, batch, empty.bool(), empty) == {}
    one = torch.tensor([2.0])
    batch = SimpleNamespace(env_rewards=one, values=one)
    real = torch.tensor([True])
    single = update._metrics(state, 0.1, 1.0, one, one, one, batch, real, real.float())
    assert single["aug_reward_mean"] == 2.0 and single["real_fraction"] == 1.0


# --- the critic's explained variance -------------------------------------------------------
GAMMA = 0.9
# chunk A, rows 0-2, truncated: bootstrapped with V(s') = 5.0 at its last row
A2 = 0.3 + GAMMA * 5.0
A1 = 0.2 + GAMMA * A2
A0 = 0.1 + GAMMA * A1
# chunk B, rows 3-5, terminated: no bootstrap (its next value 7.0 is ignored)
B2 = 0.6
B1 = 0.5 + GAMMA * B2
B0 = 0.4 + GAMMA * B1
TARGETS = [A0, A1, A2, B0, B1, B2]


def _ev_batch(values, **overrides):
    fields = dict(
        features=torch.zeros(6, 1),
        env_rewards=torch.tensor([0.1, 0.2, 0.3, 0.4, 0.5, 0.6], dtype=torch.float64),
        values=torch.tensor(values, dtype=torch.float64),
        gamma=GAMMA,
        next_values=torch.tensor([1.0, 2.0, 5.0, 3.0, 4.0, 7.0], dtype=torch.float64),
        terminateds=torch.tensor([False, False, False, False, False, True]),
        chunks=[Chunk("a", 0, 3), Chunk("b", 3, 6)],
    )
    fields.update(overrides)
    return AsorBatch(**fields)


def test_critic_ev_is_one_for_the_discounted_returns_of_each_chunk():
    assert update._critic_ev(_ev_batch(TARGETS)) == 1.0  # float64 throughout: exactly
    # the returns of one chunk bootstrapped from the other's, or not at all, are worse
    wrong = [A0 - 1.0, A1, A2, B0, B1, B2]
    t = torch.tensor(TARGETS, dtype=torch.float64)
    expected = 1.0 - float((t - torch.tensor(wrong, dtype=torch.float64)).var(unbiased=False) / t.var(unbiased=False))
    assert update._critic_ev(_ev_batch(wrong)) == pytest.approx(expected, abs=1e-12)
    assert expected < 0.99


def test_critic_ev_needs_chunks_next_values_and_terminal_flags():
    assert update._critic_ev(_ev_batch(TARGETS, chunks=None)) is None
    assert update._critic_ev(_ev_batch(TARGETS, next_values=None)) is None
    assert update._critic_ev(_ev_batch(TARGETS, terminateds=None)) is None


# --- explained variance, λ schedules, the bonus forms ----------------------------------------
def test_explained_variance_values_and_the_constant_target_cases():
    t = torch.tensor([1.0, 3.0])
    assert explained_variance(torch.tensor([1.0, 3.0]), t) == 1.0
    # residuals [1, -1] have population variance 1; targets [1, 3] too
    assert explained_variance(torch.tensor([0.0, 4.0]), t) == pytest.approx(0.0)
    t4 = torch.tensor([0.0, 2.0, 4.0, 6.0])  # population variance 5
    v4 = torch.tensor([1.0, 2.0, 4.0, 6.0])  # residual population variance 0.1875
    assert explained_variance(v4, t4) == pytest.approx(1.0 - 0.1875 / 5.0)
    for n in (0, 1):
        assert explained_variance(torch.zeros(n), torch.ones(n)) == -1.0
    assert explained_variance(torch.zeros(3), torch.full((3,), 2.0)) == -1.0


def test_scheduled_lambda_interpolates_between_points_from_the_first_one():
    spec = [[10, 1.0], [110, 0.0]]
    assert scheduled_lambda(spec, 0) == 1.0
    assert scheduled_lambda(spec, 5) == 1.0  # before the first point: its value, not an extrapolation
    assert scheduled_lambda(spec, 10) == 1.0
    assert scheduled_lambda(spec, 10.5) == pytest.approx(0.995)
    assert scheduled_lambda(spec, 60) == pytest.approx(0.5)
    assert scheduled_lambda(spec, 500) == 0.0
    assert scheduled_lambda(0.3, 99) == 0.3


def test_reward_bonus_forms_on_known_logits():
    logits = torch.tensor([0.0, 2.0, -2.0, 10.0])
    gail = reward_bonus(logits, "gail")  # -log(1 - ω), clipped above at 5
    assert gail.tolist() == pytest.approx([math.log(2.0), 2.0 + math.log1p(math.exp(-2.0)),
                                           math.log1p(math.exp(-2.0)), 5.0], abs=1e-5)
    assert reward_bonus(logits, "logit").tolist() == [0.0, 2.0, -2.0, 5.0]  # default clip 5
    assert reward_bonus(torch.tensor([1.5]), "centered").tolist() == [0.0]
    centered = reward_bonus(torch.tensor([0.0, 2.0]), "centered")
    assert centered.sum().item() == pytest.approx(0.0, abs=1e-6) and centered[1] > 0


# --- normalisers -------------------------------------------------------------------------------
def test_a_feature_of_zero_variance_normalises_to_the_clip_not_nan():
    rms = RunningMeanStd(2)
    rms.var.zero_()
    z = rms.normalize(torch.tensor([[1.0, -1.0], [0.0, 0.0]]), clip=5.0)
    assert z.tolist() == [[5.0, -5.0], [0.0, 0.0]]


def test_the_batch_normaliser_standardises_the_bonus_by_its_population_std():
    cfg = SimpleNamespace(bonus_norm="batch", bonus_clip=100.0)
    raw = torch.tensor([1.0, 3.0])  # mean 2, population std 1
    f = update._bonus_normaliser(cfg, SimpleNamespace(), raw, update_running=True)
    assert f(raw).tolist() == pytest.approx([-1.0, 1.0], abs=1e-6)
    assert f(torch.tensor([4.0])).tolist() == pytest.approx([2.0], abs=1e-6)


def test_a_warning_given_once_is_logged_once(caplog):
    message = f"diagnostics-test {uuid.uuid4()}"
    with caplog.at_level(logging.WARNING, logger="rllib_asor.asor.update"):
        update._warn_once(message)
        update._warn_once(message)
    assert [r.getMessage() for r in caplog.records].count(message) == 1


# --- encoding, top-k, concatenation ------------------------------------------------------------
def test_flatten_one_hot_encodes_a_multidiscrete_with_a_2d_nvec():
    space = gym.spaces.MultiDiscrete(np.array([[2, 3], [2, 2]]))
    out = flatten(torch.tensor([[[1, 2], [0, 1]]]), space)
    assert out.tolist() == [[0, 1, 0, 0, 1, 1, 0, 0, 1]]


def test_flatten_refuses_a_tuple_sample_with_the_wrong_number_of_parts():
    space = gym.spaces.Tuple((gym.spaces.Box(-1, 1, (1,)), gym.spaces.Discrete(2)))
    with pytest.raises(ValueError):
        flatten((torch.zeros(1, 1),), space)


def test_top_k_breaks_ties_by_position():
    x = np.zeros(64)
    x[[5, 40]] = 1.0
    assert _top_k(x, 10).tolist() == [5, 40, 0, 1, 2, 3, 4, 6, 7, 8]


def _batch(n, start, **overrides):
    f = torch.arange(start, start + n, dtype=torch.float32).reshape(n, 1)
    fields = dict(
        features=f,
        env_rewards=f[:, 0],
        values=f[:, 0],
        gamma=0.9,
        timestep=float(start) + 0.5,
        proxy_inputs=ProxyInputs(f * 2, f + 1, f + 2, f[:, 0].long()),
        next_features=f + 0.5,
        terminateds=torch.zeros(n, dtype=torch.bool),
        next_values=f[:, 0],
        chunks=[Chunk(("k", start), 0, n)],
    )
    fields.update(overrides)
    return AsorBatch(**fields)


def test_concat_batches_of_three_shifts_each_by_all_rows_before_it():
    whole = concat_batches([_batch(2, 0), _batch(3, 10), _batch(1, 20)])
    assert [(c.start, c.stop) for c in whole.chunks] == [(0, 2), (2, 5), (5, 6)]
    assert whole.proxy_inputs.features[:, 0].tolist() == [0, 2, 20, 22, 24, 40]
    assert whole.timestep == 0.5


def test_concat_batches_shifts_the_ranked_rows_and_ranks_all_rows_of_a_batch_without_them():
    first, last = _batch(3, 0, ranked=torch.tensor([2, 0])), _batch(4, 20, ranked=torch.tensor([1]))
    whole = concat_batches([first, _batch(2, 10), last])
    assert whole.ranked.tolist() == [2, 0, 3, 4, 6]
    assert concat_batches([_batch(2, 0), _batch(1, 5)]).ranked is None


def test_concat_batches_drops_an_optional_tensor_one_batch_lacks():
    whole = concat_batches([_batch(2, 0), _batch(1, 5, next_features=None, next_values=None)])
    assert whole.next_features is None and whole.next_values is None
    assert whole.terminateds.shape == (3,)


# --- the partition's inputs and ties, the state's settings -------------------------------------
def test_partition_errors_name_the_bad_argument():
    from rllib_asor.asor.partition import partition

    v, c = np.zeros(3), np.zeros(3)
    with pytest.raises(ValueError, match=r"rho_value=1\.5 is invalid"):
        partition(v, c, 1.5, 0.5)
    with pytest.raises(ValueError, match=r"rho_count=0 is invalid"):
        partition(v, c, 0.5, 0)
    with pytest.raises(ValueError, match="values must be 1-D"):
        partition(np.zeros((3, 1)), c, 0.5, 0.5)
    with pytest.raises(ValueError, match="counts contains NaN"):
        partition(v, np.array([0.0, np.nan, 0.0]), 0.5, 0.5)


def test_partition_with_rho_value_one_keeps_batch_order_among_tied_counts():
    from rllib_asor.asor.partition import partition

    mask = partition(np.array([0.0, 1.0, 2.0]), np.ones(3), 1.0, 0.5)
    assert mask.tolist() == [True, True, False]  # ⌈0.5·3⌉ = 2 of P = the whole batch, in order


def test_partition_takes_values_that_require_grad():
    from rllib_asor.asor.partition import partition

    values = torch.tensor([0.0, 3.0, 1.0, 2.0], requires_grad=True)  # a critic's output
    mask = partition(values, torch.tensor([1.0, 1.0, 0.0, 0.0]), 0.5, 0.5, mode="asor")
    assert mask.tolist() == [False, True, False, False]


def test_running_mean_std_of_a_shape_given_as_a_sequence():
    rms = RunningMeanStd([2, 3])
    rms.update(torch.arange(12.0).reshape(2, 2, 3))
    assert rms.mean.shape == (2, 3)
    assert rms.normalize(torch.zeros(1, 2, 3)).shape == (1, 2, 3)


def test_without_warm_up_the_bonus_is_on_before_the_critic_ranks_states():
    from rllib_asor.asor.config import AsorConfig

    cfg = AsorConfig(mode="srpo", lambda_warmup=False, disc_hiddens=[4], seed=0)
    state = update.AsorState(cfg, 1)
    batch = _ev_batch([0.0] * 6)  # an untrained critic: explained variance ≤ 0
    result = update.asor_update(cfg, state, None, batch, np.random.default_rng(0))
    assert result.metrics["critic_ev"] <= 0.0
    assert result.metrics["active"] == 1.0


def test_the_archive_has_the_configured_number_of_dynamics_buckets():
    from rllib_asor.asor.config import AsorConfig

    cfg = AsorConfig(mode="srpo", disc_hiddens=[4], archive_size=1, dynamics_buckets=2, seed=0)
    archive = update.AsorState(cfg, 1).archive
    for key, dynamics in (("a", 0), ("b", 2), ("c", 1)):  # 0 and 2 share a bucket of one slot
        archive.add_chunk(key, torch.ones(1, 1), torch.ones(1), dynamics, terminated=True, gamma=0.9)
    archive.end_call(0.9)
    assert len(archive) == 2
