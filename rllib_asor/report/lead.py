"""The first line of `rllib report`: the paired answer when the folder has paired seeds.

`rllib report`'s tables are training returns (exploring) summarised per group, unpaired;
`rllib compare` pairs the seeds and scores by the best evaluation recorded. When the folder holds
a baseline and a treatment with seeds in common, the report leads with `rllib compare`'s answer
so that the two never seem to disagree; otherwise its first line says its numbers are unpaired
and where the paired comparison is.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

from rllib_asor.report.compare import compare


def _f(v: float) -> str:
    return f"{v:.4g}" if math.isfinite(v) else "n/a"


def paired_lead(results_dir: str | os.PathLike[str]) -> list[str]:
    """One line per env and treatment with `rllib compare`'s answer, or one line saying that
    the report's numbers are unpaired training returns and how to get the paired ones."""
    where = f"`rllib compare {Path(results_dir)}`"
    try:
        comp = compare([results_dir])
    except ValueError as e:
        why = str(e).split(";")[0]
        return [
            "Unpaired: the numbers below are training returns (exploring) per group; for a "
            f"comparison paired by seed run {where} ({why})."
        ]
    lines = []
    for r in (r for r in comp.results if r.dynamics is None):
        source = comp.sources[r.env]
        lines.append(
            f"Paired answer ({where}, {source.kind} return, {r.pairs} pairs): {r.env}: "
            f"{r.treatment} − {r.baseline} = {r.diff_mean:+.4g}, 95% CI "
            f"[{_f(r.ci_low)}, {_f(r.ci_high)}], p {_f(r.p_value)}: {r.verdict}"
        )
    lines.append(
        "The tables below are training returns (exploring), unpaired; the paired answer above "
        "is the one to quote."
    )
    return lines
