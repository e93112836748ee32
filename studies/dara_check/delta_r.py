"""Where DARA's correction falls: the mean Δr of the source rows, split by a > 0.5 (the actions
whose dynamics differ) and by x, for every relabelled copy the runs cached in data/cache/dara/.

    OMP_NUM_THREADS=1 .venv/bin/python studies/dara_check/delta_r.py
"""

from __future__ import annotations

import json
from pathlib import Path

import torch

from rllib_asor.algorithms.dara.classifiers import delta_reward
from rllib_asor.algorithms.dara.relabel import load_classifiers, transitions
from rllib_asor.algorithms.maple.data import read_part

HERE = Path(__file__).resolve().parent


def main() -> None:
    print("| data | seed | η | σ | Δr, a > 0.5 | a > 0.5, x ≤ 3 | a > 0.5, x > 3 | a ≤ 0.5 |")
    print("|---|---|---|---|---|---|---|---|")
    rows = []
    for copy in sorted((HERE / "data" / "cache" / "dara").iterdir()):
        info = json.loads((copy / "dara.json").read_text())
        s = info["settings"]
        source = next(copy.glob("slip*/boost/mixed"))  # the copy keeps the states and actions
        obs, act, nxt = (torch.as_tensor(x) for x in transitions(read_part(source)))
        big, far = act[:, 0].numpy() > 0.5, obs[:, 0].numpy() > 3
        dr = delta_reward(load_classifiers(str(source)), obs, act, nxt, s["delta_clip"]).numpy()
        cells = [dr[big].mean(), dr[big & ~far].mean(), dr[big & far].mean(), dr[~big].mean()]
        variant = source.parent.parent.name.partition("_")[2] or "task"  # slip, slip_cover
        rows.append((variant, info["seed"], s["eta"], s["input_noise"], *cells))
    for variant, seed, eta, noise, *cells in sorted(rows):
        print(f"| {variant} | {seed} | {eta:g} | {noise:g} | "
              + " | ".join(f"{c:+.2f}" for c in cells) + " |")  # fmt: skip


if __name__ == "__main__":
    main()
