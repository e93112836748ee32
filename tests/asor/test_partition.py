"""partition(): docs/algorithm.md step 3 on hand-made arrays."""

import numpy as np
import pytest
import torch

from rllib_asor.asor import partition
from rllib_asor.asor.partition import real_set_size


def test_asor_mode_takes_top_value_then_top_count():
    values = np.array([9.0, 8.0, 7.0, 6.0, 1.0, 0.0, -1.0, -2.0])
    counts = np.array([0.0, 5.0, 1.0, 4.0, 99.0, 99.0, 99.0, 99.0])
    # P = top ceil(0.5*8)=4 by value -> idx 0..3; D_P = top ceil(0.5*4)=2 by count -> idx 1, 3.
    mask = partition(values, counts, 0.5, 0.5)
    assert mask.dtype == bool
    assert np.flatnonzero(mask).tolist() == [1, 3]


def test_high_count_low_value_states_are_never_real():
    values = np.arange(10, dtype=float)
    counts = -np.arange(10, dtype=float)  # low-value states are the most visited
    mask = partition(values, counts, 0.3, 1.0)
    assert np.flatnonzero(mask).tolist() == [7, 8, 9]


def test_sizes_use_ceilings():
    for n in (1, 2, 7, 10, 33):
        values = np.random.default_rng(n).normal(size=n)
        counts = np.random.default_rng(n + 1).normal(size=n)
        mask = partition(values, counts, 0.3, 0.3)
        assert mask.sum() == real_set_size(n, 0.3, 0.3) == int(np.ceil(0.3 * np.ceil(0.3 * n)))


def test_srpo_mode_ignores_counts_and_rho_count():
    values = np.array([3.0, 1.0, 2.0, 0.0])
    mask = partition(values, None, 0.5, 0.1, mode="srpo")
    assert np.flatnonzero(mask).tolist() == [0, 2]


def test_count_mode_ignores_values():
    values = np.array([3.0, 1.0, 2.0, 0.0])
    counts = np.array([0.0, 1.0, 2.0, 3.0])
    mask = partition(values, counts, 0.1, 0.5, mode="count")
    assert np.flatnonzero(mask).tolist() == [2, 3]


def test_random_mode_has_asor_size_and_is_seeded():
    values = np.zeros(100)
    a = partition(values, None, 0.5, 0.5, mode="random", rng=3)
    b = partition(values, None, 0.5, 0.5, mode="random", rng=3)
    c = partition(values, None, 0.5, 0.5, mode="random", rng=4)
    assert a.sum() == 25
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_torch_in_torch_out_same_result():
    values = np.array([5.0, 4.0, 3.0, 2.0, 1.0, 0.0])
    counts = np.array([1.0, 3.0, 2.0, 0.0, 0.0, 0.0])
    m_np = partition(values, counts, 0.5, 0.5)
    m_t = partition(torch.tensor(values), torch.tensor(counts), 0.5, 0.5)
    assert isinstance(m_t, torch.Tensor) and m_t.dtype == torch.bool
    assert m_t.numpy().tolist() == m_np.tolist() == [False, True, True, False, False, False]


def test_ties_keep_batch_order():
    mask = partition(np.ones(4), np.ones(4), 0.5, 0.5)
    assert np.flatnonzero(mask).tolist() == [0]


def test_rho_one_one_marks_everything_real():
    assert partition(np.arange(5.0), np.arange(5.0), 1.0, 1.0).all()


def test_empty_batch():
    assert partition(np.zeros(0), np.zeros(0), 0.5, 0.5).shape == (0,)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"rho_value": 0.0}, "rho_value"),
        ({"rho_value": 1.5}, "rho_value"),
        ({"rho_count": -0.1}, "rho_count"),
        ({"mode": "best"}, "mode"),
    ],
)
def test_bad_arguments_name_the_problem(kwargs, match):
    args = {"rho_value": 0.5, "rho_count": 0.5, "mode": "asor"} | kwargs
    with pytest.raises(ValueError, match=match):
        partition(np.zeros(4), np.zeros(4), **args)


def test_nan_values_raise():
    with pytest.raises(ValueError, match="NaN"):
        partition(np.array([0.0, np.nan]), np.zeros(2), 0.5, 0.5)


def test_asor_mode_needs_counts():
    with pytest.raises(ValueError, match="counts"):
        partition(np.zeros(4), None, 0.5, 0.5)
