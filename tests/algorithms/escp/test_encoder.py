"""The context encoder over a window equals ESCP's recurrent pass from a zero hidden state."""

from __future__ import annotations

import pytest
import torch

from rllib_asor.algorithms.escp.encoder import ContextEncoder, add_context_noise
from rllib_asor.algorithms.escp.settings import EscpSettings


def test_window_pass_equals_stepwise_gru_from_zero_state() -> None:
    torch.manual_seed(0)
    enc = ContextEncoder(5, context_dim=2, hidden=(128, 64))
    window = torch.randn(3, 16, 5)
    h = torch.zeros(3, 64)
    cell = torch.nn.GRUCell(128, 64)
    cell.weight_ih.data, cell.weight_hh.data = enc.gru.weight_ih_l0.data, enc.gru.weight_hh_l0.data
    cell.bias_ih.data, cell.bias_hh.data = enc.gru.bias_ih_l0.data, enc.gru.bias_hh_l0.data
    for t in range(16):
        h = cell(torch.nn.functional.leaky_relu(enc.fc_in(window[:, t])), h)
    expected = torch.tanh(enc.fc_out(h))
    torch.testing.assert_close(enc(window), expected)
    assert enc(window).abs().max() < 1  # tanh


def test_encoder_refuses_wrong_shape_and_noise_has_its_std() -> None:
    enc = ContextEncoder(5)
    with pytest.raises(ValueError, match=r"\[B, H, 5\]"):
        enc(torch.zeros(2, 5))
    z = torch.zeros(20000, 2)
    assert add_context_noise(z, 0.01).std().item() == pytest.approx(0.01, rel=0.05)
    assert add_context_noise(z, 0.0) is z


def test_settings_defaults_and_errors() -> None:
    s = EscpSettings()
    assert (s.context_dim, s.history_len, s.consistency_weight, s.diversity_weight) == (
        2,
        16,
        50.0,
        0.025,
    )
    assert (s.kernel, s.rbf_radius, s.rmdm_tau, s.rmdm_min_replay) == (
        "rbf_element_wise",
        3000.0,
        0.995,
        100_000,
    )
    with pytest.raises(ValueError, match=r"escp.history_len=0 .*int ≥ 1"):
        EscpSettings.from_dict({"history_len": 0})
    with pytest.raises(ValueError, match=r"escp.kernel='inner'"):
        EscpSettings.from_dict({"kernel": "inner"})
    with pytest.raises(
        ValueError, match=r"escp.windw is not an ESCP setting: allowed context_dim, "
    ):
        EscpSettings.from_dict({"windw": 3})
    with pytest.raises(ValueError, match=r"escp.history_length .*\(did you mean 'history_len'\?\)"):
        EscpSettings.from_dict({"history_length": 3})
    with pytest.raises(ValueError, match=r"escp.encoder_lr=nan .*number > 0"):
        EscpSettings.from_dict({"encoder_lr": float("nan")})
