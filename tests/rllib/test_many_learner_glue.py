"""The ASOR piece on two Learners (a real two-process gloo group, no Ray): the rewards each rank
gets and the rows its ASOR networks train on are exactly those one Learner computes on both
ranks' episodes together — its own rows' bonus, an equal share of the discriminator's and the
proxy's batches (rllib_asor/rllib/connector.py, "Several Learners") — and after every call both
ranks hold the same ASOR state (the gradients are averaged); for MAPLE+ASOR the same with the
real states of both ranks ranked together (`AsorMapleTorchLearner`, rllib_asor/rllib/learners.py)."""

from __future__ import annotations

import multiprocessing as mp
from datetime import timedelta
from pathlib import Path

import pytest
import torch
import torch.distributed as dist
from ray.rllib.core import DEFAULT_MODULE_ID, Columns

from rllib_asor.asor.trainer import AsorTrainer, even_share
from rllib_asor.rllib.learners import asor_module_id
from tests.rllib.test_glue_behaviour import (
    episodes,
    learner,
    ma_episodes,
    ma_learner,
    module_batch,
)

pytestmark = pytest.mark.heavy  # starts Ray or a subprocess: scheduled first (conftest)

SETTINGS = {
    "paper": {"preset": "paper", "lambda_": 0.3},
    # the ensemble proxy: its batches carry actions and s′ besides the states
    "robust": {"lambda_warmup": False, "lambda_": 0.3, "proxy": "ensemble"},
    "srpo": {"mode": "srpo", "preset": "paper", "lambda_": 0.3},
}
CALLS = {"first": (10, 11), "second": (20, 21)}  # the episodes' seeds on rank 0 and rank 1


def run_two_ranks(target, tmp_path: Path, *args) -> list[dict]:
    """`target(rank, store, out, *args)` in two spawned processes (one gloo group); what each
    saved to `out/<rank>.pt`."""
    ctx = mp.get_context("spawn")
    procs = [
        ctx.Process(target=target, args=(r, str(tmp_path / "store"), str(tmp_path), *args))
        for r in range(2)
    ]
    for p in procs:
        p.start()
    for p in procs:
        p.join(timeout=300)
    assert [p.exitcode for p in procs] == [0, 0]
    return [torch.load(tmp_path / f"{r}.pt") for r in range(2)]


def join_group(rank: int, store: str) -> None:
    """This process as `rank` of a two-process gloo group; a Learner left out of a collective
    makes the other fail within a minute instead of hanging."""
    torch.set_num_threads(1)
    dist.init_process_group(
        "gloo",
        init_method=f"file://{store}",
        rank=rank,
        world_size=2,
        timeout=timedelta(seconds=60),
    )


class trained_rows:
    """Within the block, `rows` holds what each ASOR network of every policy was handed to
    train on (the discriminator's features and labels, the proxy's inputs), in call order."""

    def __enter__(self) -> list[dict[str, torch.Tensor]]:
        self.rows: list[dict[str, torch.Tensor]] = []
        self.real = AsorTrainer.train_discriminator, AsorTrainer.train_proxy
        real_disc, real_proxy = self.real

        def disc(trainer, x, y, *args, **kwargs):
            self.rows.append({"disc_obs": x.clone(), "disc_label": y.clone()})
            return real_disc(trainer, x, y, *args, **kwargs)

        def proxy(trainer, x, *args, **kwargs):
            self.rows[-1] |= {"proxy_obs": x.features.clone()}
            if x.next_features is not None:
                self.rows[-1] |= {"proxy_next_obs": x.next_features.clone()}
            return real_proxy(trainer, x, *args, **kwargs)

        AsorTrainer.train_discriminator, AsorTrainer.train_proxy = disc, proxy
        return self.rows

    def __exit__(self, *exc) -> None:
        AsorTrainer.train_discriminator, AsorTrainer.train_proxy = self.real


def asor_state(lrn, policy: str = DEFAULT_MODULE_ID) -> dict[str, torch.Tensor]:
    """The policy's ASOR networks and statistics, by name."""
    trainer = lrn.module[asor_module_id(policy)].unwrapped().trainer
    return {k: v.detach().clone() for k, v in trainer.state_dict().items()}


def _pieces(lrn, eps) -> dict[str, torch.Tensor]:
    with trained_rows() as rows:
        batch = module_batch(lrn, eps)
    (trained,) = rows
    return trained | {"rewards": batch[DEFAULT_MODULE_ID][Columns.REWARDS].clone()}


def _ppo_pieces(rank: int, settings: dict) -> dict:
    lrn = learner(**settings)
    pieces = {}
    for call, seeds in CALLS.items():  # ASOR's state carries over from call to call
        pieces[call] = _pieces(lrn, episodes(seeds[rank]))
        pieces[call + "_state"] = asor_state(lrn)
    return pieces


def _all_cases(rank: int, store: str, out: str) -> None:
    """Every two-Learner case of this module, one after the other in the same gloo group
    (each builds its own Learners): spawning the pair and importing torch and RLlib in it
    costs more than the cases themselves."""
    join_group(rank, store)
    try:
        cases = {name: _ppo_pieces(rank, settings) for name, settings in SETTINGS.items()}
        cases["multi_agent"] = _ma_pieces_of_rank(rank)
        cases["maple"] = _maple_pieces_of_rank(rank)
        torch.save(cases, Path(out) / f"{rank}.pt")
        dist.barrier()  # neither rank tears gloo down while the other still talks to it
    finally:
        dist.destroy_process_group()


@pytest.fixture(scope="module")
def two_ranks(tmp_path_factory) -> list[dict]:
    """What each rank of one two-process group computed, by case (see `_all_cases`)."""
    return run_two_ranks(_all_cases, tmp_path_factory.mktemp("two_ranks"))


@pytest.mark.parametrize("name", sorted(SETTINGS))
def test_two_learners_get_what_one_learner_computes_on_both_batches(name, two_ranks):
    settings = SETTINGS[name]
    ranks = [r[name] for r in two_ranks]

    one = learner(**settings)
    call, seeds = "first", CALLS["first"]  # one Learner's networks then train differently
    whole = _pieces(one, episodes(seeds[0]) + episodes(seeds[1]))
    parts = [r[call] for r in ranks]
    # each rank's rows get the bonus one Learner gives them (rank 0's rows come first)
    n0 = parts[0]["rewards"].shape[0]
    torch.testing.assert_close(parts[0]["rewards"], whole["rewards"][:n0])
    torch.testing.assert_close(parts[1]["rewards"], whole["rewards"][n0:])
    # what the networks train on, every column: an equal share each of the one-Learner rows
    aux = sorted(k for k in whole if k != "rewards")
    if settings.get("proxy") == "ensemble":  # its inputs carry s′ besides s
        assert "proxy_next_obs" in aux
    for r in range(2):
        assert sorted(k for k in parts[r] if k != "rewards") == aux
        for key in aux:
            torch.testing.assert_close(parts[r][key], even_share(whole[key], r, 2))
    # ... and the bonus is there: the env pays only -0.02, 0 and 1
    plain = torch.tensor([-0.02, 0.0, 1.0])
    assert (whole["rewards"].reshape(-1, 1) - plain).abs().min(-1).values.max() > 1e-4
    # after every call both ranks hold the same ASOR state, and it trained
    fresh = asor_state(learner(**settings))
    for call in CALLS:
        a, b = ranks[0][call + "_state"], ranks[1][call + "_state"]
        assert a.keys() == b.keys() == fresh.keys()
        for key in a:
            torch.testing.assert_close(a[key], b[key], msg=f"{call}: {key}")
    assert any(not torch.equal(a[k], fresh[k]) for k in fresh)


MA_AGENTS = (("a0", "a1"), ("a0",))  # rank 1 has no rows of policy "p1"


def _ma_pieces(lrn, eps) -> dict[str, dict[str, torch.Tensor]]:
    """Per policy: the rows its ASOR networks trained on, its rewards (absent on a Learner
    whose agents of that policy did not act) and its ASOR state after the call."""
    with trained_rows() as rows:
        batch = module_batch(lrn, eps)
    out = {}
    for policy, trained in zip(("p0", "p1"), rows, strict=True):  # the piece goes in id order
        out[policy] = trained | {"state": asor_state(lrn, policy)}
        if policy in batch:
            out[policy]["rewards"] = batch[policy][Columns.REWARDS].clone()
    return out


def _ma_pieces_of_rank(rank: int) -> dict:
    return _ma_pieces(ma_learner(), ma_episodes(rank, MA_AGENTS[rank]))


def test_a_learner_without_rows_of_a_policy_still_takes_part_in_its_update(two_ranks):
    """Multi-agent on two Learners: a policy whose agents acted only in rank 0's episodes still
    gets ASOR's update on every rank (it is collective), with rank 0's rows ranked as one
    Learner ranks them and an equal share of the discriminator's batch on each rank."""
    ranks = [r["multi_agent"] for r in two_ranks]
    whole = _ma_pieces(ma_learner(), ma_episodes(0, MA_AGENTS[0]) + ma_episodes(1, MA_AGENTS[1]))
    for policy in ("p0", "p1"):
        one = whole[policy]
        n0 = ranks[0][policy]["rewards"].shape[0]
        torch.testing.assert_close(ranks[0][policy]["rewards"], one["rewards"][:n0])
        if policy == "p1":
            assert "rewards" not in ranks[1][policy] and n0 == one["rewards"].shape[0]
        else:
            torch.testing.assert_close(ranks[1][policy]["rewards"], one["rewards"][n0:])
        for key in (k for k in one if k not in ("rewards", "state")):
            for r in range(2):
                torch.testing.assert_close(ranks[r][policy][key], even_share(one[key], r, 2))
        for key, value in ranks[0][policy]["state"].items():
            torch.testing.assert_close(ranks[1][policy]["state"][key], value)


def _maple_pieces(learner, batch) -> dict[str, torch.Tensor]:
    """Run one MAPLE+ASOR update; the bonus MAPLE's loss got and the aux batches."""
    from rllib_asor.algorithms.maple import learner as maple_learner_module

    got: dict[str, torch.Tensor] = {}
    real_losses = maple_learner_module.maple_losses

    def losses(nets, b, **kw):
        got["bonus"] = kw["bonus"].clone()
        return real_losses(nets, b, **kw)

    maple_learner_module.maple_losses = losses
    try:
        with trained_rows() as rows:
            learner.update(batch=batch, timesteps={"maple_gradient_steps": 0})
    finally:
        maple_learner_module.maple_losses = real_losses
    (trained,) = rows
    return got | {"disc_obs": trained["disc_obs"], "proxy_obs": trained["proxy_obs"]}


def _maple_pieces_of_rank(rank: int) -> dict:
    from tests.rllib.test_soft_q_glue import maple_batch, maple_learner

    lrn = maple_learner(preset="paper", lambda_=0.1)
    pieces = _maple_pieces(lrn, maple_batch(lrn, seed=rank)[1])
    lrn.update(batch=maple_batch(lrn, seed=rank + 2)[1], timesteps={"maple_gradient_steps": 1})
    return pieces | {
        "rows_ranked": torch.tensor(lrn._asor_piece.rows_ranked), "state": asor_state(lrn)
    }


def test_two_maple_learners_rank_all_real_states_and_keep_their_own_bonus(two_ranks):
    import numpy as np
    from ray.rllib.policy.sample_batch import MultiAgentBatch, SampleBatch

    from tests.rllib.test_soft_q_glue import maple_batch, maple_learner

    ranks = [r["maple"] for r in two_ranks]

    one = maple_learner(preset="paper", lambda_=0.1)
    cols = [maple_batch(one, seed=r)[0] for r in (0, 1)]
    both = {k: np.concatenate([c[k] for c in cols]) for k in cols[0]}
    whole = _maple_pieces(one, MultiAgentBatch({DEFAULT_MODULE_ID: SampleBatch(both)}, 12))
    n0 = ranks[0]["bonus"].shape[0]
    torch.testing.assert_close(ranks[0]["bonus"], whole["bonus"][:n0])
    torch.testing.assert_close(ranks[1]["bonus"], whole["bonus"][n0:])
    for key in ("disc_obs", "proxy_obs"):
        for r in range(2):
            torch.testing.assert_close(ranks[r][key], even_share(whole[key], r, 2))
    # offline λ's timestep: each Learner counts the real rows of all Learners, call after call
    assert one._asor_piece.rows_ranked == 48
    assert [int(r["rows_ranked"]) for r in ranks] == [2 * 48, 2 * 48]
    for key, value in ranks[0]["state"].items():  # two calls later: the same ASOR state
        torch.testing.assert_close(ranks[1]["state"][key], value)
