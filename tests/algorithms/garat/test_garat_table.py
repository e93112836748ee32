"""`rllib compare --table` with GARAT beside methods that do not evaluate: GARAT's column is its
evaluation in the target, the others keep their training return (online.yaml's layout)."""

from __future__ import annotations

from pathlib import Path

from rllib_asor.report.table import render_table, table_cells
from tests.report.helpers import write_trial


def test_garat_is_scored_in_its_target_the_others_by_their_training_return(tmp_path: Path):
    env = "rllib_asor/Walker2dShift-v0"
    for seed in range(2):
        sac = {"env": env, "seed": seed, "rllib_asor_run": "SAC"}
        write_trial(tmp_path / "sac", f"s{seed}", sac, [0.0, 100.0 + seed])
        garat = {"env": env, "seed": seed, "rllib_asor_run": "GARAT"}
        write_trial(tmp_path / "garat", f"g{seed}", garat, [0.0, 900.0],  # grounded source
                    eval_returns=[0.0, 50.0 + seed])  # fmt: skip
    envs, labels, cells, sources = table_cells([tmp_path])
    assert labels == ["GARAT", "SAC"]
    assert sorted(cells[(env, "GARAT")]) == [50.0, 51.0]  # the target, not the 900 of training
    assert sorted(cells[(env, "SAC")]) == [100.0, 101.0]
    assert "evaluation" in sources[(env, "GARAT")] and "training" in sources[(env, "SAC")]
    text = render_table(envs, labels, cells, sources)
    assert "**100 ± " in text or "**100.5" in text
