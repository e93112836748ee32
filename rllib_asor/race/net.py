"""The paper's race network as an RLlib (new API stack) `TorchRLModule`.

Observation (``game_env.spaces``): a Dict of four channels-first grids (``terrain`` 4×16×16,
``items`` 2×16×16, ``targets`` 3×16×16, ``goals`` 3×16×16) and two vectors (``agent`` 32,
``destination`` 9). Action: ``MultiDiscrete([3, 3, 2, 2, 2, 2, 8, 2])``.

Architecture (paper Appendix, sizes ours and configurable through ``model_config``)::

    each grid   -> conv(3×3, stride 2) ReLU -> conv(3×3, stride 2) ReLU -> FC -> 32  (ReLU)
    each vector -> feature tokens -> multi-head self-attention -> mean pool -> FC -> 32 (ReLU)
    concat (6×32 = 192) -> policy FCN trunk -> one linear head per action dimension
                        -> value FCN -> V(s)

Attention over a vector: the vector is cut into tokens of ``attn_token_size`` consecutive
features (default 4: ``agent`` → 8 tokens, ``destination`` → 3 tokens, zero-padded at the
end); each token gets its own linear embedding (token_t = W_t·x_t + b_t, so the weight also
identifies the token, no separate position embedding: the FT-Transformer "feature tokenizer"
generalised from 1 to k features), then one pre-norm transformer block (multi-head
self-attention + a small feed-forward layer, both residual) and mean pooling. Token size 1
(one token per feature, 32 tokens) is the most expressive but cost 3.7× the CPU time of the
whole rest of the network at batch 256 (softmax over 32×32 scores per head); 4 keeps the
attention cheap while still letting it relate e.g. velocity to the distance from the cliff.

The eight action logits are concatenated (``sum(nvec)`` = 24) and read by
``TorchMultiCategorical``. Keys of ``model_config`` other than those in ``DEFAULTS`` (RLlib
adds its own, e.g. ``fcnet_hiddens``) are ignored.

Acting (exploration and inference without autograd: the env runners, evaluation) runs the
encoders and the policy head as one TorchScript trace of this module (``trace_inference``,
default on): the same parameters and outputs, bit for bit, in about half the CPU time of the
eager forward at 8 rows, which is mostly per-call Python work (docs/speed.md).
"""

from __future__ import annotations

import logging
import math
import warnings
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from ray.rllib.core.columns import Columns
from ray.rllib.core.rl_module.apis import ValueFunctionAPI
from ray.rllib.core.rl_module.rl_module import RLModule
from ray.rllib.core.rl_module.torch import TorchRLModule
from torch import nn

from rllib_asor.devices import module_device
from rllib_asor.race.action_dist import PaddedMultiCategorical

logger = logging.getLogger(__name__)

MAP_KEYS: tuple[str, ...] = ("terrain", "items", "targets", "goals")
"""Grid observations (channels first), each through its own CNN."""
VECTOR_KEYS: tuple[str, ...] = ("agent", "destination")
"""Vector observations, each through its own attention encoder."""
ACTING_KEYS: tuple[str, ...] = MAP_KEYS + VECTOR_KEYS
"""The observation's tensors in the order the acting trace takes them."""

DEFAULTS: dict[str, Any] = {
    "cnn_channels": [16, 32],
    "cnn_kernel": 3,
    "cnn_stride": 2,
    "map_embed_dim": 32,
    "attn_embed_dim": 32,
    "attn_heads": 4,
    "attn_token_size": 4,
    "vector_embed_dim": 32,
    "pi_hiddens": [128],
    "vf_hiddens": [128],
    "vf_share_encoders": True,
    "trace_inference": True,
}
"""Model settings (``model_config`` keys) and their defaults (≈150k parameters in all)."""


def race_net_settings(model_config: Mapping[str, Any] | None) -> dict[str, Any]:
    """`DEFAULTS` updated by the known keys of `model_config`; ValueError for a bad value."""
    cfg = dict(DEFAULTS)
    for key in DEFAULTS:
        if model_config is not None and key in model_config:
            cfg[key] = model_config[key]

    def bad(key: str, allowed: str) -> None:
        raise ValueError(f"race_net model_config {key}={cfg[key]!r} is invalid: allowed {allowed}")

    def pos_int(v: Any) -> bool:
        return isinstance(v, int) and not isinstance(v, bool) and v > 0

    for key in ("cnn_channels", "pi_hiddens", "vf_hiddens"):
        v = cfg[key]
        if isinstance(v, str) or not isinstance(v, list | tuple) or not all(map(pos_int, v)):
            bad(key, "a list of positive integers")
        if key == "cnn_channels" and not v:
            bad(key, "a non-empty list of positive integers")
        cfg[key] = list(v)
    for key in (
        "cnn_kernel",
        "cnn_stride",
        "map_embed_dim",
        "attn_embed_dim",
        "attn_heads",
        "attn_token_size",
        "vector_embed_dim",
    ):
        if not pos_int(cfg[key]):
            bad(key, "a positive integer")
    if cfg["attn_embed_dim"] % cfg["attn_heads"]:
        bad("attn_heads", f"a divisor of attn_embed_dim={cfg['attn_embed_dim']}")
    for key in ("vf_share_encoders", "trace_inference"):
        if not isinstance(cfg[key], bool):
            bad(key, "true or false")
    return cfg


def _mlp(in_dim: int, hiddens: list[int]) -> tuple[nn.Sequential, int]:
    layers: list[nn.Module] = []
    for h in hiddens:
        layers += [nn.Linear(in_dim, h), nn.ReLU()]
        in_dim = h
    return nn.Sequential(*layers), in_dim


class MapEncoder(nn.Module):
    """A small CNN (ReLU) and a fully connected layer: grid [B, C, H, W] → [B, out_dim]."""

    def __init__(
        self, shape: tuple[int, ...], channels: list[int], kernel: int, stride: int, out_dim: int
    ) -> None:
        super().__init__()
        layers: list[nn.Module] = []
        c_in = shape[0]
        for c in channels:
            layers += [nn.Conv2d(c_in, c, kernel, stride, padding=kernel // 2), nn.ReLU()]
            c_in = c
        self.conv = nn.Sequential(*layers, nn.Flatten())
        with torch.no_grad():
            probe = torch.zeros(1, *shape, device=module_device(self.conv))
            n_flat = self.conv(probe).shape[-1]
        self.fc = nn.Sequential(nn.Linear(n_flat, out_dim), nn.ReLU())

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.fc(self.conv(x))


class VectorAttentionEncoder(nn.Module):
    """Feature tokens → one pre-norm self-attention block → mean pool → FC: [B, D] → [B, out]."""

    def __init__(
        self, in_dim: int, token_size: int, embed_dim: int, heads: int, out_dim: int
    ) -> None:
        super().__init__()
        self.in_dim, self.token_size = in_dim, token_size
        self.num_tokens = math.ceil(in_dim / token_size)
        bound = 1.0 / math.sqrt(token_size)
        self.token_w = nn.Parameter(
            torch.empty(self.num_tokens, token_size, embed_dim).uniform_(-bound, bound)
        )
        self.token_b = nn.Parameter(torch.empty(self.num_tokens, embed_dim).uniform_(-bound, bound))
        self.norm1 = nn.LayerNorm(embed_dim)
        self.attn = nn.MultiheadAttention(embed_dim, heads, batch_first=True)
        self.norm2 = nn.LayerNorm(embed_dim)
        self.ff = nn.Sequential(nn.Linear(embed_dim, embed_dim), nn.ReLU())
        self.out = nn.Sequential(nn.LayerNorm(embed_dim), nn.Linear(embed_dim, out_dim), nn.ReLU())

    def tokens(self, x: torch.Tensor) -> torch.Tensor:
        """[B, D] → [B, T, E]: per-token linear embeddings of k consecutive features."""
        pad = self.num_tokens * self.token_size - self.in_dim
        if pad:
            x = nn.functional.pad(x, (0, pad))
        x = x.reshape(x.shape[0], self.num_tokens, self.token_size).transpose(0, 1)
        # One batched matmul over the tokens ([T, B, k] @ [T, k, E]); einsum("btk,tke->bte")
        # computes the same products through ~3× as many permute/reshape calls.
        return (torch.bmm(x, self.token_w) + self.token_b.unsqueeze(1)).transpose(0, 1)

    def self_attention(self, q: torch.Tensor) -> torch.Tensor:
        """`self.attn(q, q, q, need_weights=False)[0]` for a batch-first [B, T, E] input: the
        same projections and the same `scaled_dot_product_attention` call, in 7 torch calls
        where `nn.MultiheadAttention`'s general function makes ~30 (checks, transposes and
        copies that self-attention without masks or dropout does not need). Inference without
        autograd keeps `nn.MultiheadAttention`'s own fused path."""
        attn = self.attn
        if not (self.training or torch.is_grad_enabled()) or attn.dropout:
            return attn(q, q, q, need_weights=False)[0]
        b, t, e = q.shape
        heads = attn.num_heads
        qkv = nn.functional.linear(q, attn.in_proj_weight, attn.in_proj_bias)
        qkv = qkv.view(b, t, 3, heads, e // heads).permute(2, 0, 3, 1, 4)  # [3, B, H, T, hd]
        out = nn.functional.scaled_dot_product_attention(qkv[0], qkv[1], qkv[2])
        out = out.transpose(1, 2).reshape(b, t, e)
        return nn.functional.linear(out, attn.out_proj.weight, attn.out_proj.bias)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = self.tokens(x)
        h = h + self.self_attention(self.norm1(h))
        h = h + self.ff(self.norm2(h))
        return self.out(h.mean(dim=1))


class RaceEncoder(nn.Module):
    """All six per-key encoders; output the concatenation [B, 4·map_dim + 2·vector_dim]."""

    def __init__(self, obs_space: gym.spaces.Dict, cfg: dict[str, Any]) -> None:
        super().__init__()
        # ModuleLists in MAP_KEYS / VECTOR_KEYS order ("items" cannot be a ModuleDict key).
        self.maps = nn.ModuleList(
            MapEncoder(
                obs_space[k].shape,
                cfg["cnn_channels"],
                cfg["cnn_kernel"],
                cfg["cnn_stride"],
                cfg["map_embed_dim"],
            )
            for k in MAP_KEYS
        )
        self.vectors = nn.ModuleList(
            VectorAttentionEncoder(
                int(np.prod(obs_space[k].shape)),
                cfg["attn_token_size"],
                cfg["attn_embed_dim"],
                cfg["attn_heads"],
                cfg["vector_embed_dim"],
            )
            for k in VECTOR_KEYS
        )
        self.out_dim = (
            len(MAP_KEYS) * cfg["map_embed_dim"] + len(VECTOR_KEYS) * cfg["vector_embed_dim"]
        )

    def forward(self, obs: Mapping[str, torch.Tensor]) -> torch.Tensor:
        parts = [enc(obs[k].float()) for k, enc in zip(MAP_KEYS, self.maps, strict=True)]
        parts += [
            enc(obs[k].float().reshape(obs[k].shape[0], -1))
            for k, enc in zip(VECTOR_KEYS, self.vectors, strict=True)
        ]
        return torch.cat(parts, dim=-1)


class RaceNetModule(TorchRLModule, ValueFunctionAPI):
    """Policy + value network for the obstacle race (see the module docstring).

    Needs a Dict observation space with the keys of `MAP_KEYS` and `VECTOR_KEYS` (extra keys
    are ignored) and a MultiDiscrete action space.
    """

    def setup(self) -> None:
        obs_space, act_space = self.observation_space, self.action_space
        needed = set(MAP_KEYS) | set(VECTOR_KEYS)
        if not isinstance(obs_space, gym.spaces.Dict) or not needed <= set(obs_space.spaces):
            raise ValueError(
                f"RaceNetModule needs a Dict observation space with keys {sorted(needed)}, "
                f"got {obs_space}"
            )
        if not isinstance(act_space, gym.spaces.MultiDiscrete):
            raise ValueError(f"RaceNetModule needs a MultiDiscrete action space, got {act_space}")
        self.settings = cfg = race_net_settings(self.model_config)
        self.nvec = [int(n) for n in np.asarray(act_space.nvec).reshape(-1)]

        self.encoder = RaceEncoder(obs_space, cfg)
        self.pi_trunk, pi_dim = _mlp(self.encoder.out_dim, cfg["pi_hiddens"])
        self.pi_heads = nn.ModuleList(nn.Linear(pi_dim, n) for n in self.nvec)
        self.vf_encoder = None if cfg["vf_share_encoders"] else RaceEncoder(obs_space, cfg)
        vf_trunk, vf_dim = _mlp(self.encoder.out_dim, cfg["vf_hiddens"])
        self.vf = nn.Sequential(*vf_trunk, nn.Linear(vf_dim, 1))
        self.action_dist_cls = PaddedMultiCategorical.get_partial_dist_cls(
            space=act_space, input_lens=self.nvec
        )

    # ------------------------------------------------------------------ action distributions
    def get_inference_action_dist_cls(self) -> type:
        return self.action_dist_cls

    def get_exploration_action_dist_cls(self) -> type:
        return self.action_dist_cls

    def get_train_action_dist_cls(self) -> type:
        return self.action_dist_cls

    # ------------------------------------------------------------------ forward passes
    # RLlib's TorchRLModule walks all ~80 submodules with eval()/train() around every forward
    # call (~8 % of the race's sampling, ~2 % of its Learner). No layer here depends on the mode
    # (no dropout or batch norm; attention only picks its fused path), so the module switches
    # only when the kind of call changes: acting → eval, training → train.
    def _use_mode(self, training: bool) -> None:
        if self.training != training:
            self.train(training)

    def forward_exploration(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        self._use_mode(False)
        return self._forward_exploration(batch, **kwargs)

    def forward_inference(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        self._use_mode(False)
        return self._forward_inference(batch, **kwargs)

    def forward_train(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        self._use_mode(True)
        return RLModule.forward_train(self, batch, **kwargs)

    def logits(self, embeddings: torch.Tensor) -> torch.Tensor:
        """Concatenated logits of the action heads [B, sum(nvec)]: one matrix product with the
        heads' weights stacked (the same numbers as `cat([head(h) for head in pi_heads])`, in
        4 torch calls instead of 17, and 3 instead of 24 in the backward pass)."""
        h = self.pi_trunk(embeddings)
        weight = torch.cat([head.weight for head in self.pi_heads])
        bias = torch.cat([head.bias for head in self.pi_heads])
        return nn.functional.linear(h, weight, bias)

    def _forward(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        obs = batch[Columns.OBS]
        acting = not (self.training or torch.is_grad_enabled() or torch.compiler.is_compiling())
        # (under torch.compile, dynamo traces the eager forward itself)
        traced = self._acting_trace(obs) if acting and self.settings["trace_inference"] else None
        if traced is None:
            return {Columns.ACTION_DIST_INPUTS: self.logits(self.encoder(obs))}
        return {Columns.ACTION_DIST_INPUTS: traced(*(obs[k] for k in ACTING_KEYS))}

    def _acting_trace(self, obs: Mapping[str, torch.Tensor]) -> Any:
        """`_ActingPolicy(self)` traced on `obs` (None where tracing fails: eager then). The
        trace shares this module's parameters, so new weights loaded in place reach it; it is
        traced again when the parameters move (another device, replaced tensors)."""
        first = next(self.parameters())
        key = (first.device, first.data_ptr())
        cached = self.__dict__.get("_trace")
        if cached is None or cached[0] != key:
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")  # torch.jit's deprecation notice
                    trace = torch.jit.trace(
                        _ActingPolicy(self), tuple(obs[k] for k in ACTING_KEYS), check_trace=False
                    )
            except Exception as e:  # a torch without TorchScript: act eagerly
                logger.warning("race_net: acting without a trace (%s: %s)", type(e).__name__, e)
                trace = None
            cached = self.__dict__["_trace"] = (key, trace)
        return cached[1]

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state.pop("_trace", None)  # a copy traces its own parameters when it acts
        return state

    def _forward_train(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        emb = self.encoder(batch[Columns.OBS])
        out = {Columns.ACTION_DIST_INPUTS: self.logits(emb)}
        if self.vf_encoder is None:
            out[Columns.EMBEDDINGS] = emb
        return out

    def compute_values(
        self, batch: dict[str, Any], embeddings: torch.Tensor | None = None
    ) -> torch.Tensor:
        """V(s) of shape [B] (reuses `embeddings` from `_forward_train` when shared)."""
        if embeddings is None:
            enc = self.encoder if self.vf_encoder is None else self.vf_encoder
            embeddings = enc(batch[Columns.OBS])
        return self.vf(embeddings).squeeze(-1)


class _ActingPolicy(nn.Module):
    """The policy's logits from the observation's tensors in `ACTING_KEYS` order (what the
    acting trace records: a trace takes tensors, not a dict)."""

    def __init__(self, module: RaceNetModule) -> None:
        super().__init__()
        self.module = module

    def forward(self, *tensors: torch.Tensor) -> torch.Tensor:
        return self.module.logits(self.module.encoder(dict(zip(ACTING_KEYS, tensors, strict=True))))
