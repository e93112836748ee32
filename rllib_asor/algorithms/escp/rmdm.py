"""RMDM: ESCP's representation loss (Relational Matrix Determinant Maximization).

Faithful to ESCP `algorithms/RMDM.py` (`RMDMLoss.rmdm_loss_timing`, `RMDMLoss.construct_loss`,
`get_loss_dpp`, `get_rbf_matrix`) as `algorithms/sac.py` (`SAC.sac_update`) calls it:

1. Per task in the batch, the batch mean of z (with gradient). A task seen for the first time
   starts its moving average at that mean; tasks absent from the batch keep theirs.
2. The moving averages move: m ← τ·m + (1 − τ)·(batch mean) (τ = `rmdm_tau` 0.995).
3. Consistency: std = √( mean over rows of the mean over z's dimensions of (z − m_task)² ),
   around the *updated* moving averages (detached; detached as a whole when std < 1e−3).
4. Diversity: −log det(K + 1e−3·I), K an RBF kernel over this batch's task means plus the
   moving averages of the tasks absent from it; `rbf_element_wise` (ESCP's default):
   K_ij = mean_d exp(−α (x_id − x_jd)²), `rbf`: exp(−α Σ_d (x_id − x_jd)²), α = `rbf_radius`.
5. loss = w_c·consistency + w_d·diversity, or w_c·consistency alone while std ≥ 0.1
   (ESCP's weights: `consistency_loss_weight` 50, `diversity_loss_weight` 0.025).

The switch-on rule (`rmdm_switched_on`, from `SAC.sac_update`) decides whether the loss trains
the encoder; the moving averages move on every call, as in ESCP. Fewer than two tasks in the
batch: no loss and no update (ESCP returns None).

Task "slots" are row indices into the moving-average table (ESCP indexes
`history_env_mean[task − 1]`); `TaskSlots` maps arbitrary `dynamics_id` values to slots.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

KERNELS = ("rbf_element_wise", "rbf")


def rbf_matrix(x: torch.Tensor, radius: float, element_wise: bool) -> torch.Tensor:
    """ESCP `get_rbf_matrix(x, x, alpha=radius, element_wise_exp)`: [n, d] → [n, n]."""
    sq = (x.unsqueeze(0) - x.unsqueeze(1)).pow(2) * radius
    return (-sq).exp().mean(-1) if element_wise else (-sq.sum(-1)).exp()


def diversity_loss(means: torch.Tensor, kernel: str = "rbf_element_wise", radius: float = 3000.0):
    """ESCP `get_loss_dpp`: −log det(K + 1e−3·I) over task means [n, d]."""
    if kernel not in KERNELS:
        raise ValueError(f"kernel={kernel!r} is not allowed; expected one of {KERNELS}")
    k = rbf_matrix(means, radius, element_wise=kernel == "rbf_element_wise")
    eye = torch.eye(means.shape[0], device=means.device, dtype=means.dtype)
    return -torch.logdet(k + 1e-3 * eye)


@dataclass
class RmdmResult:
    """One RMDM evaluation. `loss` is None when the batch held fewer than two tasks."""

    loss: torch.Tensor | None
    consistency: torch.Tensor | None
    diversity: torch.Tensor | None
    std: float
    num_tasks: int


def rmdm_loss(
    z: torch.Tensor,
    slots: torch.Tensor,
    means: torch.Tensor,
    seen: torch.Tensor,
    *,
    tau: float = 0.995,
    consistency_weight: float = 50.0,
    diversity_weight: float = 0.025,
    kernel: str = "rbf_element_wise",
    rbf_radius: float = 3000.0,
) -> RmdmResult:
    """RMDM on encoder outputs `z` [N, d] with task slots `slots` [N] (module docstring).

    Updates the moving averages `means` [T, d] and the flags `seen` [T] in place (no grad).
    """
    if z.dim() != 2 or slots.shape != z.shape[:1]:
        raise ValueError(f"rmdm_loss: z {tuple(z.shape)} and slots {tuple(slots.shape)} differ")
    tasks, inverse = torch.unique(slots, sorted=True, return_inverse=True)
    if tasks.numel() <= 1:
        return RmdmResult(None, None, None, 0.0, int(tasks.numel()))
    counts = torch.bincount(inverse, minlength=tasks.numel()).to(z.dtype)
    batch_means = torch.zeros(tasks.numel(), z.shape[1], dtype=z.dtype, device=z.device)
    batch_means = batch_means.index_add(0, inverse, z) / counts.unsqueeze(-1)
    with torch.no_grad():
        new = ~seen[tasks]
        means[tasks[new]] = batch_means[new].detach().to(means.dtype)  # first sight
        current = means.clone()
        current[tasks] = batch_means.detach().to(means.dtype)
        means.mul_(tau).add_((1.0 - tau) * current)  # absent tasks: current == history
        absent = seen.clone()
        absent[tasks] = False
        seen[tasks] = True
    repres = torch.cat([batch_means, means[absent].to(z.dtype)], 0)
    diversity = diversity_loss(repres, kernel, rbf_radius)
    var = (z - means[slots].to(z.dtype)).pow(2).mean(-1).mean()
    std = var.sqrt()
    consistency = std.detach() if std.item() < 1e-3 else std
    loss = consistency_weight * consistency
    if std.item() < 0.1:
        loss = loss + diversity_weight * diversity
    return RmdmResult(loss, consistency, diversity, float(std.item()), int(tasks.numel()))


def rmdm_switched_on(
    replay_size: int,
    batch_tasks: int,
    num_tasks: int,
    min_replay: int = 100_000,
    min_task_fraction: float = 0.5,
) -> bool:
    """ESCP `SAC.sac_update`: the encoder trains once the replay buffer holds
    ≥ `minimal_repre_rp_size` steps and the batch has ≥ int(0.5 · `task_num`) tasks."""
    return replay_size >= min_replay and batch_tasks >= int(min_task_fraction * num_tasks)


class TaskSlots:
    """Maps `dynamics_id` values to rows of a fixed table of `capacity` slots (first come,
    first served); `ids` [capacity] int64 (−1 = free) is the table, kept by the caller
    (a module buffer, so it is checkpointed)."""

    def __init__(self, ids: torch.Tensor) -> None:
        self.ids = ids

    def lookup(self, dynamics_ids: torch.Tensor, *, add: bool = True) -> torch.Tensor:
        """Slots of `dynamics_ids` [N]; unknown ids get free slots (`add`) or −1."""
        uniq, inverse = torch.unique(dynamics_ids, return_inverse=True)
        table = {int(v): i for i, v in enumerate(self.ids.tolist()) if v >= 0}
        out = []
        for value in uniq.tolist():
            slot = table.get(int(value))
            if slot is None and add:
                free = (self.ids < 0).nonzero()
                if free.numel() == 0:
                    raise ValueError(
                        f"escp.max_tasks={self.ids.numel()} is too small: the env reported more "
                        f"distinct info['dynamics_id'] values (new: {int(value)}); raise "
                        "escp.max_tasks to at least the number of training tasks"
                    )
                slot = int(free[0])
                self.ids[slot] = int(value)
                table[int(value)] = slot
            out.append(-1 if slot is None else slot)
        return torch.tensor(out, dtype=torch.long, device=dynamics_ids.device)[inverse]
