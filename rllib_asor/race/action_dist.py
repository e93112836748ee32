"""A MultiDiscrete action distribution computed on one padded tensor.

RLlib's `TorchMultiCategorical` keeps one `TorchCategorical` per action head and loops over them
for every sample, log-probability, entropy and KL: on the race (8 heads) that is ~8 small torch
calls per quantity, in every sampling step and every PPO minibatch. `PaddedMultiCategorical`
is the same distribution with the heads' logits gathered into one [..., heads, max_k] tensor
(padding at -inf), so each quantity is one `log_softmax`, one gather or one sum. Sampling draws
from the same categorical probabilities (one `torch.multinomial` call for all heads). Unlike
RLlib 2.60's class, `temperatures` (if given) divide the heads' logits.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache
from typing import Any

import torch
from ray.rllib.core.distribution.torch.torch_distribution import (
    TorchCategorical,
    TorchDeterministic,
    TorchMultiCategorical,
)


@lru_cache(maxsize=32)
def _padding_index(
    input_lens: tuple[int, ...], device: torch.device
) -> tuple[torch.Tensor, torch.Tensor]:
    """[heads, max_k] positions into the logits (padding → one past the end) and the valid mask,
    on `device` (cached per device: no host-to-device copy per call)."""
    max_k, start, rows, valid = max(input_lens), 0, [], []
    for n in input_lens:
        rows.append([start + k if k < n else sum(input_lens) for k in range(max_k)])
        valid.append([k < n for k in range(max_k)])
        start += n
    return torch.tensor(rows, device=device), torch.tensor(valid, device=device)


class PaddedMultiCategorical(TorchMultiCategorical):
    """`TorchMultiCategorical`'s distribution, with each quantity computed for all heads at once.

    Build it as RLlib builds its distributions: `PaddedMultiCategorical.get_partial_dist_cls(
    input_lens=space.nvec)` and then `.from_logits(logits)`.
    """

    def __init__(self, logits: torch.Tensor, input_lens: Sequence[int]) -> None:
        super(TorchMultiCategorical, self).__init__()  # RLlib's Distribution base, no heads
        self._logits = logits
        self._input_lens = tuple(int(n) for n in input_lens)
        index, self._valid = _padding_index(self._input_lens, logits.device)
        pad = logits.new_full((*logits.shape[:-1], 1), float("-inf"))
        padded = torch.cat([logits, pad], dim=-1)[..., index]  # [..., heads, max_k]
        self._padded_logits = padded
        self._log_probs = torch.log_softmax(padded, dim=-1)

    @property
    def _cats(self) -> list[TorchCategorical]:  # type: ignore[override]
        """Per-head `TorchCategorical`s, for RLlib code that walks them (built on demand)."""
        return [TorchCategorical(logits=x) for x in torch.split(self._logits, self._input_lens, -1)]

    def _finite_log_probs(self) -> torch.Tensor:
        """Log-probabilities with 0 at the padding, where the probability is 0 (so the p · log p
        terms there are 0, not NaN)."""
        return self._log_probs.masked_fill(~self._valid, 0.0)

    def sample(self) -> torch.Tensor:
        with torch.no_grad():
            probs = self._log_probs.exp()
            flat = probs.reshape(-1, probs.shape[-1])
            return torch.multinomial(flat, 1).reshape(probs.shape[:-1])

    def logp(self, value: torch.Tensor) -> torch.Tensor:
        picked = self._log_probs.gather(-1, value.long().unsqueeze(-1)).squeeze(-1)
        return picked.sum(-1)

    def entropy(self) -> torch.Tensor:
        return -(self._log_probs.exp() * self._finite_log_probs()).sum((-1, -2))

    def kl(self, other: Any) -> torch.Tensor:
        if not isinstance(other, PaddedMultiCategorical):
            return super().kl(other)  # through the per-head `_cats`
        mine, theirs = self._finite_log_probs(), other._finite_log_probs()
        return (self._log_probs.exp() * (mine - theirs)).sum((-1, -2))

    def to_deterministic(self) -> TorchDeterministic:
        return TorchDeterministic(loc=self._padded_logits.argmax(-1))

    @classmethod
    def from_logits(
        cls,
        logits: torch.Tensor,
        input_lens: Sequence[int],
        temperatures: Sequence[float] | None = None,
        **kwargs: Any,
    ) -> PaddedMultiCategorical:
        if sum(input_lens) != logits.shape[-1]:
            raise ValueError(
                f"input_lens {list(input_lens)} must sum to the logits' size {logits.shape[-1]}"
            )
        if temperatures and any(t != 1.0 for t in temperatures):
            scale = torch.repeat_interleave(
                logits.new_tensor([1.0 / t for t in temperatures]),
                torch.tensor(list(input_lens), device=logits.device),
            )
            logits = logits * scale
        return cls(logits, input_lens)
