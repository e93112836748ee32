"""The discriminator's input normaliser: fixed on the expert rows (GAIfO's default), or per
update on the expert and policy rows together (`input_norm_rows: round`, the GARAT authors'
per-round normalisation), over all Learners of a real gloo group; GARAT's `disc_norm`."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch
import torch.distributed as dist
import torch.multiprocessing as mp

from rllib_asor.algorithms.common.demonstrations import Demonstrations
from rllib_asor.algorithms.gaifo.settings import GaifoSettings
from rllib_asor.algorithms.gaifo.trainer import GaifoTrainer
from rllib_asor.algorithms.garat.settings import GaratSettings


def _trainer(rows: str) -> GaifoTrainer:
    """Expert transitions s → s + 1 from s = 0 and 2: feature rows (s, s′) = (0, 1), (2, 3)."""
    obs = np.array([[0.0], [2.0]], np.float32)
    demos = Demonstrations.of(obs, obs + 1, np.zeros(2), np.zeros(2, bool))
    settings = GaifoSettings(input_norm_rows=rows, disc_steps=1, disc_hiddens=(4,))
    return GaifoTrainer(settings, demos, "cpu")


def _policy(trainer: GaifoTrainer, states: list[float]) -> torch.Tensor:
    s = torch.tensor([[x] for x in states])
    return trainer.features(s, s + 1)


def test_expert_rows_fix_the_normaliser_once():
    trainer = _trainer("expert")
    assert trainer.disc.mean.tolist() == [1.0, 2.0] and trainer.disc.std.tolist() == [1.0, 1.0]
    trainer.update(_policy(trainer, [4.0, 6.0]))
    assert trainer.disc.mean.tolist() == [1.0, 2.0] and trainer.disc.std.tolist() == [1.0, 1.0]


def test_round_rows_refit_it_on_expert_and_policy_rows_at_every_update():
    trainer = _trainer("round")
    trainer.update(_policy(trainer, [4.0, 6.0]))  # s: 0, 2, 4, 6 → mean 3, variance 5
    assert trainer.disc.mean.tolist() == [3.0, 4.0]
    assert trainer.disc.std.tolist() == pytest.approx([math.sqrt(5.0)] * 2)
    trainer.update(_policy(trainer, [2.0, 2.0]))  # s: 0, 2, 2, 2 → mean 1.5, variance 0.75
    assert trainer.disc.mean.tolist() == [1.5, 2.5]
    assert trainer.disc.std.tolist() == pytest.approx([math.sqrt(0.75)] * 2)


def _round_on_rank(rank: int, world: int, init_file: str, out: str) -> None:
    torch.set_num_threads(1)
    dist.init_process_group("gloo", init_method=f"file://{init_file}", rank=rank, world_size=world)
    try:
        trainer = _trainer("round")
        trainer.update(_policy(trainer, [[4.0, 6.0], [8.0, 10.0]][rank]))
        torch.save({"mean": trainer.disc.mean, "std": trainer.disc.std}, Path(out) / f"{rank}.pt")
        dist.barrier()  # neither rank tears gloo down while the other still talks to it
    finally:
        dist.destroy_process_group()


def test_round_rows_of_two_learners_give_both_the_same_normaliser(tmp_path):
    mp.spawn(_round_on_rank, args=(2, str(tmp_path / "init"), str(tmp_path)), nprocs=2)
    ranks = [torch.load(tmp_path / f"{r}.pt") for r in range(2)]
    # s: 0, 2 (the expert rows, counted once) and 4, 6, 8, 10 → mean 5, variance 70 / 6
    for r in ranks:
        assert r["mean"].tolist() == [5.0, 6.0]
        assert r["std"].tolist() == pytest.approx([math.sqrt(70 / 6)] * 2)


def test_garat_forwards_its_disc_norm_and_refuses_other_values():
    from rllib_asor.algorithms.garat.grounding import gaifo_block

    assert GaratSettings().disc_norm == "target" and GaifoSettings().input_norm_rows == "expert"
    for norm, rows in (("target", "expert"), ("round", "round")):
        block = gaifo_block(GaratSettings(disc_norm=norm), "/data/target.npz", 3)
        assert GaifoSettings(**block).input_norm_rows == rows
    with pytest.raises(
        ValueError, match=r"garat.disc_norm='batch' is not allowed; expected target"
    ):
        GaratSettings(disc_norm="batch")
    with pytest.raises(ValueError, match=r"gaifo.input_norm_rows='all' is not allowed"):
        GaifoSettings(input_norm_rows="all")
