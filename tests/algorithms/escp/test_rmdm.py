"""RMDM on hand-made tensors: what each term does, its sign and scale (ESCP algorithms/RMDM.py)."""

from __future__ import annotations

import math

import pytest
import torch

from rllib_asor.algorithms.escp.rmdm import (
    TaskSlots,
    diversity_loss,
    rmdm_loss,
    rmdm_switched_on,
)


def _table(tasks: int = 4, dim: int = 2) -> tuple[torch.Tensor, torch.Tensor]:
    return torch.zeros(tasks, dim), torch.zeros(tasks, dtype=torch.bool)


def _spread(z: torch.Tensor, slots: torch.Tensor) -> float:
    return sum(z[slots == s].var(0).sum().item() for s in slots.unique())


def test_consistency_gradient_pulls_same_task_z_together() -> None:
    torch.manual_seed(0)
    slots = torch.tensor([0] * 8 + [1] * 8)
    z = (torch.randn(16, 2) * 0.3 + (slots[:, None] * 2 - 1) * 0.5).requires_grad_(True)
    means, seen = _table()
    res = rmdm_loss(z, slots, means, seen)
    assert res.std >= 0.1  # ESCP: consistency alone while the spread is large
    res.loss.backward()
    moved = (z - 0.01 * z.grad).detach()
    assert _spread(moved, slots) < _spread(z.detach(), slots)


def test_diversity_gradient_pushes_task_means_apart() -> None:
    slots = torch.tensor([0] * 4 + [1] * 4)
    base = torch.tensor([[0.0, 0.0]] * 4 + [[0.02, 0.01]] * 4)
    z = (base + 1e-4 * torch.randn(8, 2)).requires_grad_(True)
    means, seen = _table()
    res = rmdm_loss(z, slots, means, seen)
    assert res.std < 0.1  # diversity is on
    res.loss.backward()
    moved = (z - 1e-6 * z.grad).detach()
    gap = lambda x: (x[4:].mean(0) - x[:4].mean(0)).norm().item()  # noqa: E731
    assert gap(moved) > gap(z.detach())


def test_terms_match_hand_computation_and_weights() -> None:
    slots = torch.tensor([0, 0, 1, 1])
    z = torch.tensor([[0.0, 0.0], [0.02, 0.0], [0.1, 0.1], [0.1, 0.12]])
    means, seen = _table()
    res = rmdm_loss(z, slots, means, seen, consistency_weight=50.0, diversity_weight=0.025)
    m0, m1 = z[:2].mean(0), z[2:].mean(0)  # first sight: the averages start at the batch means
    dev = torch.cat([z[:2] - m0, z[2:] - m1])
    std = dev.pow(2).mean().sqrt().item()
    assert res.consistency.item() == pytest.approx(std, rel=1e-5)
    k = torch.exp(-3000.0 * (m0 - m1).pow(2)).mean().item()
    div = -math.log((1 + 1e-3) ** 2 - k**2)
    assert res.diversity.item() == pytest.approx(div, rel=1e-4)
    assert res.consistency.item() > 0 and res.diversity.item() > -2 * math.log(1 + 1e-3) - 1e-6
    assert res.loss.item() == pytest.approx(50.0 * std + 0.025 * div, rel=1e-4)


def test_large_spread_uses_consistency_only() -> None:
    slots = torch.tensor([0, 0, 1, 1])
    z = torch.tensor([[0.5, 0.5], [-0.5, -0.5], [0.9, -0.9], [-0.9, 0.9]])
    res = rmdm_loss(z, slots, *_table())
    assert res.std >= 0.1
    assert res.loss.item() == pytest.approx(50.0 * res.consistency.item(), rel=1e-6)


def test_diversity_falls_as_task_means_separate() -> None:
    near = diversity_loss(torch.tensor([[0.0, 0.0], [0.01, 0.0]]))
    far = diversity_loss(torch.tensor([[0.0, 0.0], [0.5, 0.5]]))
    assert far < near
    assert far.item() == pytest.approx(-2 * math.log(1 + 1e-3), abs=1e-6)  # K → I


def test_moving_averages_follow_escp_and_keep_absent_tasks() -> None:
    means, seen = _table(tasks=3)
    z1 = torch.tensor([[0.0, 0.0], [0.2, 0.2], [1.0, 1.0]])
    rmdm_loss(z1, torch.tensor([0, 1, 2]), means, seen, tau=0.9)
    assert torch.allclose(means, z1) and seen.all()
    z2 = torch.tensor([[1.0, 0.0], [0.0, 1.0]])
    res = rmdm_loss(z2, torch.tensor([0, 1]), means, seen, tau=0.9)
    assert torch.allclose(means[0], 0.9 * z1[0] + 0.1 * z2[0])
    assert torch.allclose(means[1], 0.9 * z1[1] + 0.1 * z2[1])
    assert torch.allclose(means[2], z1[2])  # absent: unchanged, but in the kernel
    k = lambda a, b: torch.exp(-3000.0 * (a - b).pow(2)).mean()  # noqa: E731
    pts = [z2[0], z2[1], z1[2]]
    kmat = torch.stack([torch.stack([k(a, b) for b in pts]) for a in pts]) + 1e-3 * torch.eye(3)
    assert res.diversity.item() == pytest.approx(-torch.logdet(kmat).item(), rel=1e-4)


def test_single_task_batch_gives_no_loss_and_no_update() -> None:
    means, seen = _table()
    res = rmdm_loss(torch.ones(3, 2), torch.tensor([1, 1, 1]), means, seen)
    assert res.loss is None and res.num_tasks == 1
    assert not seen.any() and (means == 0).all()


def test_switch_on_rule() -> None:
    assert not rmdm_switched_on(99_999, 40, 40)
    assert not rmdm_switched_on(100_000, 19, 40)
    assert rmdm_switched_on(100_000, 20, 40)


def test_task_slots_map_ids_and_refuse_overflow() -> None:
    slots = TaskSlots(torch.full((2,), -1, dtype=torch.long))
    out = slots.lookup(torch.tensor([907, 5, 907]))
    assert out.tolist() == [1, 0, 1]  # sorted unique ids take free slots in order
    assert slots.lookup(torch.tensor([5])).tolist() == [0]
    with pytest.raises(ValueError, match="escp.max_tasks=2"):
        slots.lookup(torch.tensor([6]))
