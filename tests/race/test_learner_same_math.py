"""The race Learner's overhead cuts compute what they replace: race_net's lean attention, token
embedding and stacked action heads against the formulation they replace, the sync-free PPO loss
against RLlib's, and one whole update of the race PPO Learner against RLlib's own PPO Learner."""

import copy

import numpy as np
import pytest
import torch
from ray.rllib.algorithms.ppo.torch.ppo_torch_learner import PPOTorchLearner
from ray.rllib.core import DEFAULT_MODULE_ID, Columns
from ray.rllib.evaluation.postprocessing import Postprocessing
from ray.rllib.utils.metrics import NUM_ENV_STEPS_SAMPLED_LIFETIME

import game_env
from rllib_asor.algorithms.ppo.lean import LeanPPOTorchLearner
from rllib_asor.algorithms.ppo.loss import SyncFreePPOLossMixin
from rllib_asor.race.config import race_ppo_config
from rllib_asor.race.net import MAP_KEYS, VECTOR_KEYS, RaceNetModule

SPACES = {DEFAULT_MODULE_ID: (game_env.observation_space(), game_env.action_space())}


def race_net() -> RaceNetModule:
    obs_space, act_space = SPACES[DEFAULT_MODULE_ID]
    return RaceNetModule(observation_space=obs_space, action_space=act_space, model_config={})


def race_obs(n: int, seed: int = 0) -> dict[str, torch.Tensor]:
    space = game_env.observation_space()
    space.seed(seed)
    rows = [space.sample() for _ in range(n)]
    return {k: torch.as_tensor(np.stack([r[k] for r in rows])) for k in space.spaces}


def reference_forward(m: RaceNetModule, obs: dict[str, torch.Tensor]) -> tuple:
    """race_net as first written: einsum token embeddings, `nn.MultiheadAttention`'s own
    forward, one Linear call per action head."""
    enc = m.encoder
    parts = [e(obs[k].float()) for k, e in zip(MAP_KEYS, enc.maps, strict=True)]
    for k, v in zip(VECTOR_KEYS, enc.vectors, strict=True):
        x = obs[k].float().reshape(obs[k].shape[0], -1)
        x = torch.nn.functional.pad(x, (0, v.num_tokens * v.token_size - v.in_dim))
        x = x.reshape(x.shape[0], v.num_tokens, v.token_size)
        h = torch.einsum("btk,tke->bte", x, v.token_w) + v.token_b
        q = v.norm1(h)
        h = h + v.attn(q, q, q, need_weights=False)[0]
        h = h + v.ff(v.norm2(h))
        parts.append(v.out(h.mean(dim=1)))
    emb = torch.cat(parts, dim=-1)
    trunk = m.pi_trunk(emb)
    logits = torch.cat([head(trunk) for head in m.pi_heads], dim=-1)
    return logits, m.vf(emb).squeeze(-1)


def test_race_net_logits_values_and_gradients_equal_the_reference_formulation():
    torch.manual_seed(0)
    m = race_net()
    obs = race_obs(64)
    results = []
    for forward in ("lean", "reference"):
        m.zero_grad(set_to_none=True)
        if forward == "lean":
            out = m.forward_train({Columns.OBS: obs})
            logits = out[Columns.ACTION_DIST_INPUTS]
            values = m.compute_values({Columns.OBS: obs}, out[Columns.EMBEDDINGS])
        else:
            logits, values = reference_forward(m, obs)
        loss = (logits.log_softmax(-1) * torch.linspace(-1, 1, logits.shape[-1])).sum() + (
            values**2
        ).mean()
        loss.backward()
        grads = {n: p.grad.clone() for n, p in m.named_parameters()}
        results.append((logits.detach(), values.detach(), grads))
    (la, va, ga), (lb, vb, gb) = results
    torch.testing.assert_close(la, lb, rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(va, vb, rtol=1e-5, atol=1e-6)
    assert ga.keys() == gb.keys() and len(ga) > 50
    for name in ga:
        torch.testing.assert_close(ga[name], gb[name], rtol=1e-4, atol=1e-6, msg=name)


def test_race_net_acting_without_autograd_keeps_attentions_fused_path_and_the_same_actions():
    torch.manual_seed(0)
    m = race_net()
    obs = race_obs(16)
    train_logits = m.forward_train({Columns.OBS: obs})[Columns.ACTION_DIST_INPUTS]
    with torch.no_grad():
        act_logits = m.forward_inference({Columns.OBS: obs})[Columns.ACTION_DIST_INPUTS]
    assert not m.training
    torch.testing.assert_close(act_logits, train_logits.detach(), rtol=1e-5, atol=1e-5)


def learner(cls: type, grad_clip: float | None = None):
    """The race PPO Learner (seeded, so every build starts from the same weights) as `cls`."""
    config = race_ppo_config(max_episode_steps=20).learners(learner_class=cls)
    config = config.training(
        minibatch_size=32, num_epochs=2, train_batch_size=64, grad_clip=grad_clip
    )
    return config.debugging(seed=3).build_learner(spaces=SPACES)


def loss_batch(n: int = 48) -> dict:
    g = torch.Generator().manual_seed(1)
    mask = torch.rand(n, generator=g) > 0.25
    mask[-1] = False
    return {
        Columns.OBS: race_obs(n, seed=1),
        Columns.ACTIONS: torch.stack(
            [torch.randint(0, k, (n,), generator=g) for k in game_env.action_space().nvec], -1
        ),
        Columns.ACTION_LOGP: -torch.rand(n, generator=g) * 10,
        Columns.ACTION_DIST_INPUTS: torch.randn(n, 24, generator=g),
        Postprocessing.ADVANTAGES: torch.randn(n, generator=g),
        Postprocessing.VALUE_TARGETS: torch.randn(n, generator=g),
        Columns.LOSS_MASK: mask,
    }


@pytest.mark.parametrize("use_kl_loss", [True, False])
def test_sync_free_ppo_loss_equals_rllibs_loss_metrics_and_gradients(use_kl_loss):
    lrn = learner(LeanPPOTorchLearner)
    module = lrn.module[DEFAULT_MODULE_ID]
    config = copy.copy(lrn.config.get_config_for_module(DEFAULT_MODULE_ID))
    config.use_kl_loss = use_kl_loss
    batch = loss_batch()
    out = {}
    for name, fn in (
        ("rllib", PPOTorchLearner.compute_loss_for_module),
        ("ours", SyncFreePPOLossMixin.compute_loss_for_module),
    ):
        module.zero_grad(set_to_none=True)
        fwd = module.forward_train(batch)
        loss = fn(lrn, module_id=DEFAULT_MODULE_ID, config=config, batch=batch, fwd_out=fwd)
        loss.backward()
        metrics = {
            k: float(torch.as_tensor(lrn.metrics.peek((DEFAULT_MODULE_ID, k))).detach())
            for k in (
                "policy_loss",
                "vf_loss",
                "vf_loss_unclipped",
                "vf_explained_var",
                "entropy",
                "mean_kl_loss",
            )
        }
        grads = {n: p.grad.clone() for n, p in module.named_parameters()}
        out[name] = (loss.detach(), metrics, grads)
    (la, ma, ga), (lb, mb, gb) = out["rllib"], out["ours"]
    torch.testing.assert_close(la, lb, rtol=1e-5, atol=1e-6)
    assert ma == pytest.approx(mb, rel=1e-5, abs=1e-6)
    assert ma["policy_loss"] != 0 and ma["vf_loss"] > 0
    for name in ga:
        torch.testing.assert_close(ga[name], gb[name], rtol=1e-4, atol=1e-6, msg=name)


@pytest.mark.parametrize("grad_clip", [None, 0.05])
def test_one_update_of_the_race_ppo_learner_equals_rllibs_ppo_learner(grad_clip, race_episodes):
    """Same recorded episodes, same seeds: after one update (2 epochs × 2 minibatches, no
    shuffle) the race Learner (lean net path, sync-free loss, one gradient check, fused Adam)
    holds the weights RLlib's own PPOTorchLearner arrives at, and reports the same losses; with
    a `grad_clip` that binds, too (RLlib's gradient postprocessing then runs)."""
    results, weights = {}, {}
    for cls in (PPOTorchLearner, LeanPPOTorchLearner):
        lrn = learner(cls, grad_clip)
        assert type(lrn) is cls
        res = lrn.update(
            episodes=copy.deepcopy(race_episodes),
            timesteps={NUM_ENV_STEPS_SAMPLED_LIFETIME: 64},
            num_epochs=2,
            minibatch_size=32,
            shuffle_batch_per_epoch=False,
        )
        results[cls] = {
            k: float(v.peek())
            for k, v in res[DEFAULT_MODULE_ID].items()
            if k in ("policy_loss", "vf_loss", "entropy", "mean_kl_loss", "total_loss")
        }
        if grad_clip is not None:  # the clip binds: RLlib logs the norm it clipped from
            assert (
                float(res[DEFAULT_MODULE_ID]["gradients_default_optimizer_global_norm"].peek())
                > grad_clip
            )
        weights[cls] = {
            n: p.detach().clone() for n, p in lrn.module[DEFAULT_MODULE_ID].named_parameters()
        }
    assert len(results[PPOTorchLearner]) == 5
    assert results[PPOTorchLearner] == pytest.approx(
        results[LeanPPOTorchLearner], rel=1e-4, abs=1e-6
    )
    start = {
        n: p.detach()
        for n, p in learner(PPOTorchLearner).module[DEFAULT_MODULE_ID].named_parameters()
    }
    moved = 0
    for name, w in weights[PPOTorchLearner].items():
        ours = weights[LeanPPOTorchLearner][name]
        if name.endswith("attn.in_proj_bias"):
            # The key bias adds the same number to every attention score of a query, so its
            # gradient is 0 up to rounding, and Adam scales that rounding noise up to steps of
            # ~lr/10: there the two Learners agree to 1e-5, elsewhere to 1e-6.
            e = w.shape[0] // 3
            torch.testing.assert_close(ours[e : 2 * e], w[e : 2 * e], rtol=0, atol=1e-5)
            ours, w = torch.cat([ours[:e], ours[2 * e :]]), torch.cat([w[:e], w[2 * e :]])
        torch.testing.assert_close(ours, w, rtol=1e-4, atol=1e-6, msg=name)
        moved += not torch.equal(weights[PPOTorchLearner][name], start[name])
    assert moved > 50  # the update changed (nearly) every parameter
