"""ESCP's context encoder (its "environment probe", `ep`).

ESCP `models/policy.py` (`Policy.__init__`: `self.ep = RNNBase(obs_dim + act_dim, ep_dim,
ep_hidden_size, ep_activation, ep_layer_type)`) with `parameter/Parameter.py`'s recurrent
setting: `ep_hidden_size = [128, 64]`, `ep_layer_type = ['fc', 'gru', 'fc']`,
`ep_activations = ['leaky_relu', 'linear', 'tanh']`, `ep_dim = 2`. Inputs are (s_t, a_{t−1});
with `rnn_fix_length = H` ESCP re-runs the GRU from a zero hidden state over the last H steps
at every inference step (`Policy.inference_rnn_fix_one_action`) and over zero-padded H-step
windows in training (`MemoryArray.sample_fix_length_sub_trajs`), so a stateless module over a
window computes exactly what ESCP computes.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn


class ContextEncoder(nn.Module):
    """z = tanh(fc(GRU(LeakyReLU(fc(x))))) at the last step of a window, from a zero state.

    Args:
        input_dim: obs_dim + act_dim (one step of the window is (s_t, a_{t−1})).
        context_dim: size of z (ESCP's `ep_dim`, 2).
        hidden: (fc width, GRU width), ESCP's `ep_hidden_size` (128, 64).
    """

    def __init__(self, input_dim: int, context_dim: int = 2, hidden: Sequence[int] = (128, 64)):
        super().__init__()
        if len(hidden) != 2:
            raise ValueError(f"hidden={tuple(hidden)!r} is not allowed; expected (fc, gru) sizes")
        self.input_dim = int(input_dim)
        self.fc_in = nn.Linear(self.input_dim, int(hidden[0]))
        self.act = nn.LeakyReLU()
        self.gru = nn.GRU(int(hidden[0]), int(hidden[1]), batch_first=True)
        self.fc_out = nn.Linear(int(hidden[1]), int(context_dim))

    def forward(self, window: torch.Tensor) -> torch.Tensor:
        """`window` [B, H, input_dim] (oldest step first) → z [B, context_dim]."""
        if window.dim() != 3 or window.shape[-1] != self.input_dim:
            raise ValueError(
                f"ContextEncoder expects a [B, H, {self.input_dim}] window, got "
                f"{tuple(window.shape)}"
            )
        _, h_last = self.gru(self.act(self.fc_in(window)))  # zero initial hidden state
        return torch.tanh(self.fc_out(h_last[-1]))


def add_context_noise(z: torch.Tensor, std: float) -> torch.Tensor:
    """ESCP's information bottleneck (`Policy.meta_forward`, `bottle_neck`/`bottle_sigma`):
    z + N(0, std²) when sampling in training; std 0 returns z."""
    if std <= 0:
        return z
    return z + torch.randn_like(z) * std
