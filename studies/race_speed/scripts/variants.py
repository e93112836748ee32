"""Variants for learner_ab.py, switched on a built Learner between updates: "old" = RLlib's Adam
and a Learner connector with autograd; "drop" = drop_bootstrap_rows; "denorm" = flush denormals;
"bf16" = bfloat16 autocast (both tried, neither helped)."""

# ruff: noqa: F811
import torch
from ray.rllib.connectors.learner import GeneralAdvantageEstimation
from ray.rllib.core.learner.learner import Learner

from rllib_asor.algorithms.common.pipeline import insert_beside
from rllib_asor.algorithms.ppo.lean import DropMaskedRows

_piece = None


def _grad_batch(L):
    def f(training_data):
        with torch.enable_grad():
            return Learner._make_batch_if_necessary(L, training_data)

    return f


def apply(L, v):
    global _piece
    if _piece is None:
        _piece = DropMaskedRows()
    pipeline = L._learner_connector
    pipeline.connectors = [c for c in pipeline.connectors if c is not _piece]
    if "drop" in v:
        insert_beside(pipeline, GeneralAdvantageEstimation, _piece, before=False)
    fused = "old" not in v
    for opt in L._optimizer_parameters:
        for g in opt.param_groups:
            g["fused"] = fused or None
            g["foreach"] = False if fused else None
    if "old" in v:
        L._make_batch_if_necessary = _grad_batch(L)
    else:
        L.__dict__.pop("_make_batch_if_necessary", None)


_orig_update = {}


def extra(L, v):
    torch.set_flush_denormal("denorm" in v)
    cls_update = type(L)._update
    if "bf16" in v:

        def upd(batch, **kw):
            with torch.autocast("cpu", dtype=torch.bfloat16):
                return cls_update(L, batch, **kw)

        L._update = upd
    else:
        L.__dict__.pop("_update", None)


_apply = apply


def apply(L, v):
    _apply(L, v)
    extra(L, v)
