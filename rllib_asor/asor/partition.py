"""Step 3 of ASOR: split a batch into D_P ("real": accessible and good) and D_Q.

P is the top ⌈ρ1·|B|⌉ states by value; D_P is the top ⌈ρ2·|P|⌉ of P by the visitation proxy.
Ties keep batch order (stable sort), so the result is a pure function of its inputs.
"""

from __future__ import annotations

import math
import sys
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np

if TYPE_CHECKING:
    import torch

from rllib_asor.asor.config import MODES, effective_rhos

ArrayT = TypeVar("ArrayT", np.ndarray, "torch.Tensor")


def real_set_size(n: int, rho_value: float, rho_count: float, mode: str = "asor") -> int:
    """|D_P| for a batch of n states: ⌈ρ2·⌈ρ1·n⌉⌉ with the mode's effective ρs."""
    r1, r2 = effective_rhos(rho_value, rho_count, mode)
    return math.ceil(r2 * math.ceil(r1 * n)) if n > 0 else 0


def partition(
    values: ArrayT,
    counts: ArrayT | None,
    rho_value: float,
    rho_count: float,
    mode: str = "asor",
    rng: np.random.Generator | torch.Generator | int | None = None,
) -> ArrayT:
    """Boolean mask of D_P over a 1-D batch (numpy in → numpy out, torch in → torch out).

    Args:
        values: V(s) per state, shape [N].
        counts: visitation proxy c(s) per state (higher = visited more), shape [N]; may be
            None for modes that do not use it (`srpo`, `random`).
        rho_value: ρ1 ∈ (0, 1]; `count` mode uses 1.
        rho_count: ρ2 ∈ (0, 1]; `srpo` mode uses 1.
        mode: `asor` (value, then count), `srpo` (value only), `count` (count only), or
            `random` (a uniformly random subset of the same size as `asor`'s D_P).
        rng: randomness for `random` mode (a numpy Generator, a torch Generator, or a seed).
    """
    if mode not in MODES:
        raise ValueError(f"partition: mode={mode!r} is invalid: allowed {' | '.join(MODES)}")
    for name, rho in (("rho_value", rho_value), ("rho_count", rho_count)):
        if not (isinstance(rho, int | float) and 0.0 < rho <= 1.0):
            raise ValueError(f"partition: {name}={rho!r} is invalid: allowed a number in (0, 1]")
    is_torch = _torch_type(values, "Tensor")
    v = _as_numpy(values, "values")
    n = v.shape[0]
    uses_counts = mode in ("asor", "count")
    c = None
    if uses_counts:
        if counts is None:
            raise ValueError(f"partition: mode={mode!r} needs counts (got None)")
        c = _as_numpy(counts, "counts")
        if c.shape != v.shape:
            raise ValueError(f"partition: counts shape {c.shape} must equal values shape {v.shape}")

    mask = np.zeros(n, dtype=bool)
    if n > 0:
        r1, r2 = effective_rhos(rho_value, rho_count, mode)
        if mode == "random":
            size = real_set_size(n, rho_value, rho_count, mode)
            chosen = _random_generator(rng).choice(n, size=size, replace=False)
        else:
            top_value = _top_k(v, math.ceil(r1 * n)) if r1 < 1.0 else np.arange(n)
            if uses_counts:
                k = math.ceil(r2 * len(top_value))
                chosen = top_value[_top_k(c[top_value], k)]
            else:
                chosen = top_value
        mask[chosen] = True
    if is_torch:
        return sys.modules["torch"].from_numpy(mask).to(values.device)
    return mask


def _top_k(x: np.ndarray, k: int) -> np.ndarray:
    """Indices of the k largest entries, ties broken by position (stable)."""
    return np.argsort(-x, kind="stable")[:k]


def _as_numpy(x: np.ndarray | torch.Tensor, name: str) -> np.ndarray:
    arr = x.detach().cpu().numpy() if _torch_type(x, "Tensor") else np.asarray(x)
    if arr.ndim != 1:
        raise ValueError(f"partition: {name} must be 1-D, got shape {arr.shape}")
    arr = arr.astype(np.float64, copy=False)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"partition: {name} contains NaN or inf")
    return arr


def _random_generator(
    rng: np.random.Generator | torch.Generator | int | None,
) -> np.random.Generator:
    if isinstance(rng, np.random.Generator):
        return rng
    if _torch_type(rng, "Generator"):
        torch = sys.modules["torch"]
        seed = torch.randint(0, 2**31 - 1, (1,), generator=rng, device=rng.device)
        return np.random.default_rng(int(seed))
    return np.random.default_rng(rng)


def _torch_type(x: Any, name: str) -> bool:
    """isinstance(x, torch.<name>) without importing torch: a torch object means torch is
    already loaded (this module stays importable without it, like `rllib_asor.asor`)."""
    torch = sys.modules.get("torch")
    return torch is not None and isinstance(x, getattr(torch, name))
