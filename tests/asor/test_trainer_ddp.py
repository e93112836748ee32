"""`AsorTrainer` on two ranks of a real gloo process group (two processes, no Ray): each rank
trains on its equal share of the same batch with averaged gradients, so both end with the same
networks and optimiser moments, unlike a trainer that steps on the whole batch alone."""

from __future__ import annotations

from pathlib import Path

import torch
import torch.distributed as dist
import torch.multiprocessing as mp

from tests.asor.test_state_behaviour import episodes
from tests.asor.test_trainer import trainer

WORLD = 2


def _train(rank: int, world: int, init_file: str, out: str) -> None:
    torch.set_num_threads(1)
    dist.init_process_group("gloo", init_method=f"file://{init_file}", rank=rank, world_size=world)
    try:
        t = trainer()
        batch = episodes(1)
        result = t.step(batch, minibatch_size=16, share=(rank, world))
        torch.save(
            {
                "params": [p.detach() for p in t.parameters()],
                "disc_optimizer": t.disc_optimizer.state_dict(),
                "metrics": dict(result.metrics),
            },
            Path(out) / f"{rank}.pt",
        )
        dist.barrier()  # neither rank tears gloo down while the other still talks to it
    finally:
        dist.destroy_process_group()


def _flat(state: dict) -> list[torch.Tensor]:
    moments = state["disc_optimizer"]["state"]
    return [v for s in moments.values() for v in s.values() if isinstance(v, torch.Tensor)]


def test_two_ranks_train_equal_shares_into_one_state(tmp_path):
    mp.spawn(_train, args=(WORLD, str(tmp_path / "init"), str(tmp_path)), nprocs=WORLD)
    ranks = [torch.load(tmp_path / f"{r}.pt", weights_only=False) for r in range(WORLD)]
    for a, b in zip(ranks[0]["params"], ranks[1]["params"], strict=True):
        assert torch.equal(a, b)
    for a, b in zip(_flat(ranks[0]), _flat(ranks[1]), strict=True):
        assert torch.equal(a, b)
    assert _flat(ranks[0]), "the discriminator's optimiser took no step"

    untrained = trainer()
    alone = trainer()
    alone.step(episodes(1), minibatch_size=16)
    before = [p.detach() for p in untrained.parameters()]
    assert any(not torch.equal(a, b) for a, b in zip(ranks[0]["params"], before, strict=True))
    # stepping on the whole batch alone is another update than two averaged half shares
    assert any(
        not torch.allclose(a, b.detach())
        for a, b in zip(ranks[0]["params"], alone.parameters(), strict=True)
    )
    # each rank's metrics are those of its own share: the two differ
    m0, m1 = ranks[0]["metrics"], ranks[1]["metrics"]
    assert m0.keys() == m1.keys() and any(m0[k] != m1[k] for k in ("disc_loss", "rnd_loss"))
