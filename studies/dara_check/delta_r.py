"""Where DARA's correction falls: the mean Δr of the source rows, split by a > 0.5 (the actions
whose dynamics differ) and by x, for every relabelled copy the runs cached in data/cache/dara/.

    OMP_NUM_THREADS=1 .venv/bin/python studies/dara_check/delta_r.py
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch

from rllib_asor.algorithms.dara.classifiers import delta_reward
from rllib_asor.algorithms.dara.relabel import load_classifiers

HERE = Path(__file__).resolve().parent


def main() -> None:
    import run  # this folder's run.py: the task and the data's behaviour policy

    def source_rows(variant: str):
        starts = run.DATA_STARTS[variant]
        episodes = run.rollout(run.behaviour(1), "boost", run.EPISODES["boost"], 1, starts)
        obs = torch.tensor(np.concatenate([e[0][:-1] for e in episodes]))
        act = torch.tensor(np.concatenate([e[1] for e in episodes]))
        nxt = torch.tensor(np.concatenate([e[0][1:] for e in episodes]))
        return obs, act, nxt  # make_data's source part

    print("| data | seed | η | σ | Δr, a > 0.5 | a > 0.5, x ≤ 3 | a > 0.5, x > 3 | a ≤ 0.5 |")
    print("|---|---|---|---|---|---|---|---|")
    rows = []
    for copy in sorted((HERE / "data" / "cache" / "dara").iterdir()):
        info = json.loads((copy / "dara.json").read_text())
        s = info["settings"]
        part = next(copy.glob("slip*/*/mixed"))
        variant = part.parent.parent.name.partition("_")[2]
        obs, act, nxt = source_rows(variant)
        big, far = act[:, 0].numpy() > 0.5, obs[:, 0].numpy() > 3
        dr = delta_reward(load_classifiers(str(part)), obs, act, nxt, s["delta_clip"]).numpy()
        cells = [dr[big].mean(), dr[big & ~far].mean(), dr[big & far].mean(), dr[~big].mean()]
        rows.append((variant or "task", info["seed"], s["eta"], s["input_noise"], *cells))
    for variant, seed, eta, noise, *cells in sorted(rows):
        print(f"| {variant} | {seed} | {eta:g} | {noise:g} | "
              + " | ".join(f"{c:+.2f}" for c in cells) + " |")  # fmt: skip


if __name__ == "__main__":
    main()
