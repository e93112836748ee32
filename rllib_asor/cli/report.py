"""`rllib report RESULTS_DIR`: markdown tables and PNG learning curves from Tune results.

Reads every trial directory under RESULTS_DIR (a folder holding ``result.json``, one JSON object
per training iteration, and ``params.json``, the trial's algorithm config), groups trials by
env and method (``PPO``, ``PPO+ASOR``, ``SAC+SRPO``, ...) and writes ``report.md``,
``summary.json`` and one ``curves_<env>.png`` per env into the output folder. Files are written
atomically (temp file + ``os.replace``).
"""

from __future__ import annotations

import argparse
import difflib
import json
import math
import os
import re
import sys
import tempfile
import warnings
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rllib_asor.report.stats import bootstrap_ci, iqm, mean_std

DEFAULT_METRIC = "env_runners/episode_return_mean"
DEFAULT_X = "num_env_steps_sampled_lifetime"
FALLBACK_X = "training_iteration"
RESULT_FILE = "result.json"
PARAMS_FILE = "params.json"

KNOWN_ALGOS = (
    "APPO",
    "IMPALA",
    "PPO",
    "SAC",
    "DQN",
    "CQL",
    "IQL",
    "MARWIL",
    "BC",
    "TQC",
    "DreamerV3",
)
"""RLlib algorithm names recognised in trial and experiment folder names (longest match wins)."""

MODE_SUFFIX = {"asor": "+ASOR", "srpo": "+SRPO"}
"""Method suffix per ASOR partition mode; other modes become ``+ASOR(<mode>)``."""

EXTRA_METRIC_RE = re.compile(r"(^|/)(race|asor)/")
"""Result keys eligible as extra columns: ``race/...`` and ``asor/...`` metrics."""

HEADLINE_ASOR = ("disc_acc", "aug_reward_mean", "bonus_share", "lambda", "active")
"""ASOR metrics shown by default (``--columns all`` shows every one)."""
HEADLINE_RACE = ("success_rate", "trapped_rate", "unnecessary_jump_rate", "goal_reward")
"""Race metrics shown by default: the paper's table, over all maps (per map: ``--columns all``)."""


@dataclass
class Trial:
    """One Tune trial: its folder, config and per-iteration flattened results."""

    path: Path
    experiment: str
    params: dict[str, Any]
    rows: list[dict[str, Any]]
    env: str = ""
    method: str = ""

    def series(self, key: str) -> np.ndarray:
        """Values of `key` per iteration as floats (NaN where absent or not a number)."""
        return np.array([_as_float(r.get(key)) for r in self.rows], dtype=float)

    def has(self, key: str) -> bool:
        """Whether any iteration reports a finite value for `key`."""
        return bool(np.isfinite(self.series(key)).any())

    def final(self, key: str, last_n: int) -> float:
        """Mean of the last `last_n` finite values of `key` (NaN if none)."""
        vals = self.series(key)
        vals = vals[np.isfinite(vals)]
        return float(np.mean(vals[-last_n:])) if vals.size else math.nan


@dataclass
class GroupStats:
    """Summary of one (env, method) group's final values."""

    env: str
    method: str
    n: int
    mean: float
    std: float
    ci_low: float
    ci_high: float
    iqm: float
    env_steps: float
    finals: list[float]
    extra: dict[str, tuple[float, float]] = field(default_factory=dict)
    """Extra column key -> (mean, std) over the group's trials that report it."""


@dataclass
class Report:
    """Everything `make_report` writes, for callers that want the numbers."""

    metric: str
    x: str
    last_n: int
    groups: list[GroupStats]
    trials: list[Trial]
    columns: list[str]
    notes: list[str]


# --------------------------------------------------------------------------- reading


def _as_float(v: Any) -> float:
    if isinstance(v, bool) or v is None:
        return math.nan
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def flatten(d: dict[str, Any], prefix: str = "") -> Iterator[tuple[str, Any]]:
    """Yield ``("a/b/c", value)`` for a nested result dict, skipping the ``config`` copy."""
    for k, v in d.items():
        if not prefix and k == "config":
            continue
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            yield from flatten(v, key + "/")
        else:
            yield key, v


def _read_rows(path: Path, notes: list[str]) -> list[dict[str, Any]]:
    """Parse a Tune ``result.json``; drop broken lines, keep the last report per iteration."""
    by_iter: dict[Any, dict[str, Any]] = {}
    bad = 0
    with path.open(encoding="utf-8") as f:
        for i, line in enumerate(f):
            line = line.strip()
            if not line:
                continue
            try:
                obj = json.loads(line)
            except json.JSONDecodeError:
                bad += 1
                continue
            if not isinstance(obj, dict):
                bad += 1
                continue
            row = dict(flatten(obj))
            # A restored trial re-reports iterations after its checkpoint: the later one wins.
            by_iter[row.get("training_iteration", f"line{i}")] = row
    if bad:
        notes.append(f"{path}: skipped {bad} unreadable line(s)")
    rows = list(by_iter.values())
    rows.sort(key=lambda r: _as_float(r.get("training_iteration")))
    return rows


def find_trials(results_dir: str | os.PathLike[str], notes: list[str] | None = None) -> list[Trial]:
    """All trial folders (holding ``result.json`` with at least one row) under `results_dir`."""
    root = Path(results_dir).expanduser()
    notes = notes if notes is not None else []
    if not root.is_dir():
        raise ValueError(f"results directory {str(root)!r} does not exist or is not a directory")
    trials: list[Trial] = []
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames[:] = sorted(d for d in dirnames if not d.startswith("checkpoint_"))
        if RESULT_FILE not in filenames:
            continue
        tdir = Path(dirpath)
        rows = _read_rows(tdir / RESULT_FILE, notes)
        if not rows:
            notes.append(f"{tdir}: empty {RESULT_FILE}, trial skipped")
            continue
        params: dict[str, Any] = {}
        if (tdir / PARAMS_FILE).is_file():
            try:
                loaded = json.loads((tdir / PARAMS_FILE).read_text(encoding="utf-8"))
                params = loaded if isinstance(loaded, dict) else {}
            except json.JSONDecodeError:
                notes.append(f"{tdir}: unreadable {PARAMS_FILE}")
        experiment = tdir.parent.name if tdir != root else root.name
        trials.append(Trial(path=tdir, experiment=experiment, params=params, rows=rows))
    if not trials:
        raise ValueError(f"no trial results ({RESULT_FILE}) found under {str(root)!r}")
    return trials


# --------------------------------------------------------------------------- grouping


def algo_name(trial: Trial) -> str:
    """Algorithm from the trial folder name (``PPO_CartPole-v1_...``), else the experiment name."""
    by_len = sorted(KNOWN_ALGOS, key=len, reverse=True)
    head = trial.path.name.split("_", 1)[0]
    # Our ASOR trainables are named Asor<run> (rllib_asor.rllib.trainable): AsorPPO -> PPO.
    bare = head[4:] if head.lower().startswith("asor") else head
    for name in by_len:
        if bare.lower() == name.lower():
            return name
    for token in re.split(r"[^A-Za-z0-9]+", trial.experiment):
        for name in by_len:
            if token.lower() == name.lower():
                return name
    return head or trial.experiment


def asor_block(params: dict[str, Any]) -> Any:
    """The ASOR settings in a trial's params (top-level ``asor`` or ``learner_config_dict.asor``)."""
    if "asor" in params and params["asor"] is not None:
        return params["asor"]
    lcd = params.get("learner_config_dict")
    if isinstance(lcd, dict) and lcd.get("asor") is not None:
        return lcd["asor"]
    return None


def asor_mode(params: dict[str, Any]) -> str | None:
    """ASOR partition mode of a trial, or None when the trial does not use ASOR."""
    block = asor_block(params)
    if block is None or block is False:
        return None
    if isinstance(block, dict):
        return str(block.get("mode", "asor"))
    # Tune writes objects it cannot serialise as their repr, e.g. "AsorConfig(..., mode='srpo', ...)".
    m = re.search(r"\bmode\s*[=:]\s*['\"]?(\w+)", str(block))
    return m.group(1) if m else "asor"


def method_name(trial: Trial) -> str:
    """``PPO``, ``PPO+ASOR``, ``SAC+SRPO``, ``PPO+ASOR(count)``, ..."""
    mode = asor_mode(trial.params)
    if mode is None:
        return algo_name(trial)
    return algo_name(trial) + MODE_SUFFIX.get(mode, f"+ASOR({mode})")


def lookup(params: dict[str, Any], dotted: str) -> Any:
    """Value at a dotted key in params (also tried under ``learner_config_dict``); KeyError if absent."""
    for base in (params, params.get("learner_config_dict")):
        cur: Any = base
        for part in dotted.split("."):
            if isinstance(cur, dict) and part in cur:
                cur = cur[part]
            else:
                break
        else:
            return cur
    raise KeyError(dotted)


def assign_groups(trials: Iterable[Trial], group_by: str | None = None) -> None:
    """Set each trial's ``env`` and ``method`` (``KEY=value`` when `group_by` is given)."""
    for t in trials:
        env = t.params.get("env")
        t.env = str(env) if env not in (None, "") else "unknown-env"
        if group_by:
            try:
                value = lookup(t.params, group_by)
            except KeyError:
                value = "<missing>"
            t.method = (
                f"{group_by}={json.dumps(value) if isinstance(value, list | dict) else value}"
            )
        else:
            t.method = method_name(t)


# --------------------------------------------------------------------------- statistics


def _is_headline(key: str) -> bool:
    """A headline race/... or asor/... metric (over all maps and policies)."""
    parts = key.split("/")
    if len(parts) < 2:
        return False
    group, name = parts[-2], parts[-1]
    return (group == "race" and name in HEADLINE_RACE) or (
        group == "asor" and name in HEADLINE_ASOR
    )


def headline_columns(keys: Iterable[str]) -> list[str]:
    """The default extra columns: each headline metric once, from its shortest key (RLlib
    reports race metrics both as `race/...` and `env_runners/race/...`)."""
    best: dict[str, str] = {}
    for key in sorted(k for k in keys if _is_headline(k)):
        tail = "/".join(key.split("/")[-2:])
        if tail not in best or len(key) < len(best[tail]):
            best[tail] = key
    return sorted(best.values())


def summarize(
    results_dir: str | os.PathLike[str],
    metric: str = DEFAULT_METRIC,
    x: str = DEFAULT_X,
    last_n: int = 1,
    group_by: str | None = None,
    columns: Sequence[str] | None = None,
) -> Report:
    """Read, group and summarise the trials under `results_dir` (no files written)."""
    if last_n < 1:
        raise ValueError(f"last_n must be >= 1, got {last_n}")
    notes: list[str] = []
    trials = find_trials(results_dir, notes)
    assign_groups(trials, group_by)

    with_metric = [t for t in trials if t.has(metric)]
    if not with_metric:
        keys = sorted({k for t in trials for r in t.rows for k in r})
        close = difflib.get_close_matches(metric, keys, n=5, cutoff=0.4)
        hint = f"; similar keys: {', '.join(close)}" if close else ""
        raise ValueError(
            f"metric {metric!r} is not reported by any of {len(trials)} trial(s){hint}"
        )
    for t in trials:
        if t not in with_metric:
            notes.append(f"{t.path}: no {metric!r}, trial left out")

    if not all(t.has(x) for t in with_metric):
        notes.append(f"x key {x!r} missing in some trials; curves use {FALLBACK_X!r}")
        x = FALLBACK_X

    found = {k for t in with_metric for r in t.rows for k in r if EXTRA_METRIC_RE.search(k)}
    if columns is None:
        columns = headline_columns(found)
    elif list(columns) == ["all"]:
        columns = sorted(found)
    columns = [c for c in columns if c != metric]

    groups: list[GroupStats] = []
    keyed: dict[tuple[str, str], list[Trial]] = {}
    for t in with_metric:
        keyed.setdefault((t.env, t.method), []).append(t)
    for (env, method), members in sorted(keyed.items()):
        finals = [t.final(metric, last_n) for t in members]
        mean, std = mean_std(finals)
        lo, hi = bootstrap_ci(finals)
        steps = float(np.nanmean([t.final(x, 1) for t in members]))
        extra = {c: mean_std([t.final(c, last_n) for t in members]) for c in columns}
        groups.append(
            GroupStats(
                env, method, len(members), mean, std, lo, hi, iqm(finals), steps, finals, extra
            )
        )
    return Report(metric, x, last_n, groups, with_metric, list(columns), notes)


# --------------------------------------------------------------------------- writing


def _fmt(v: float) -> str:
    if not math.isfinite(v):
        return "n/a"
    if v == 0 or 0.01 <= abs(v) < 1e6:
        return f"{v:.2f}"
    return f"{v:.3g}"


def _pm(mean: float, std: float) -> str:
    return f"{_fmt(mean)} ± {_fmt(std)}" if math.isfinite(mean) else "n/a"


def _slug(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("_") or "env"


def _atomic_write(path: Path, data: bytes) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp's 0600 -> the usual mode of a new file
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _jsonable(obj: Any) -> Any:
    """NaN/inf -> None, recursively, so summary.json is strict JSON."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_jsonable(v) for v in obj]
    return obj


def _curve(trial: Trial, metric: str, x: str) -> tuple[np.ndarray, np.ndarray]:
    xs, ys = trial.series(x), trial.series(metric)
    ok = np.isfinite(xs) & np.isfinite(ys)
    order = np.argsort(xs[ok], kind="stable")  # np.interp needs increasing x
    return xs[ok][order], ys[ok][order]


def plot_env(report: Report, env: str, path: Path) -> None:
    """One PNG: mean ± std across seeds per method over `report.x`, for one env."""
    import matplotlib

    matplotlib.use("Agg")
    import io

    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5), dpi=100)
    try:
        for g in (g for g in report.groups if g.env == env):
            curves = [
                _curve(t, report.metric, report.x)
                for t in report.trials
                if t.env == env and t.method == g.method
            ]
            curves = [(cx, cy) for cx, cy in curves if cx.size]
            if not curves:
                continue
            hi = max(float(cx.max()) for cx, _ in curves)
            lo = min(float(cx.min()) for cx, _ in curves)
            grid = np.linspace(lo, hi, 200) if hi > lo else np.array([lo])
            # Each seed is interpolated only inside the range it reached (no extrapolation).
            ys = np.array(
                [
                    np.where(
                        (grid >= cx.min()) & (grid <= cx.max()), np.interp(grid, cx, cy), np.nan
                    )
                    for cx, cy in curves
                ]
            )
            count = np.isfinite(ys).sum(axis=0)
            keep = count > 0
            with warnings.catch_warnings():  # all-NaN grid columns are dropped by `keep`
                warnings.simplefilter("ignore", RuntimeWarning)
                mean = np.nanmean(ys, axis=0)
                std = np.nan_to_num(np.nanstd(ys, axis=0, ddof=1))  # sample std, as in the table
            label = f"{g.method} (n={g.n})"
            if keep.sum() == 1:
                ax.errorbar(grid[keep], mean[keep], yerr=std[keep], fmt="o", label=label, capsize=3)
            else:
                (line,) = ax.plot(grid[keep], mean[keep], label=label)
                ax.fill_between(
                    grid[keep],
                    (mean - std)[keep],
                    (mean + std)[keep],
                    color=line.get_color(),
                    alpha=0.2,
                    linewidth=0,
                )
        ax.set_title(f"{env}: {report.metric}")
        ax.set_xlabel(report.x)
        ax.set_ylabel(f"{report.metric} (mean ± std over seeds)")
        ax.grid(alpha=0.3)
        ax.legend(loc="best", fontsize="small")
        fig.tight_layout()
        buf = io.BytesIO()
        fig.savefig(buf, format="png")
    finally:
        plt.close(fig)
    _atomic_write(path, buf.getvalue())


def render_markdown(report: Report, results_dir: Path, plots: dict[str, str]) -> str:
    """The report as markdown: one table per env, its curve, the trials, notes."""
    out = [
        "# Training report",
        "",
        f"- results: `{results_dir}`",
        f"- metric: `{report.metric}`; final value per trial = mean of its last "
        f"{report.last_n} iteration(s)",
        "- per method: trials (seeds), final mean ± std (sample std), 95% bootstrap CI of the "
        "mean (BCa, 5,000 resamples), IQM (25% trimmed mean), env steps "
        f"(mean final `{report.x}`)",
        "",
    ]
    for env in sorted({g.env for g in report.groups}):
        out += [f"## {env}", ""]
        head = ["method", "trials", "final mean ± std", "95% CI", "IQM", "env steps"]
        head += [f"`{c}`" for c in report.columns]
        out += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for g in (g for g in report.groups if g.env == env):
            ci = f"[{_fmt(g.ci_low)}, {_fmt(g.ci_high)}]" if g.n > 1 else "n/a (1 trial)"
            cells = [
                g.method,
                str(g.n),
                _pm(g.mean, g.std),
                ci,
                _fmt(g.iqm),
                f"{g.env_steps:,.0f}" if math.isfinite(g.env_steps) else "n/a",
            ]
            cells += [_pm(*g.extra[c]) for c in report.columns]
            out.append("| " + " | ".join(cells) + " |")
        if env in plots:
            out += ["", f"![{env} learning curves]({plots[env]})"]
        out.append("")
    out += [
        "## Trials",
        "",
        "| env | method | trial | iterations | final |",
        "|---|---|---|---|---|",
    ]
    for t in sorted(report.trials, key=lambda t: (t.env, t.method, str(t.path))):
        rel = os.path.relpath(t.path, results_dir)
        out.append(
            f"| {t.env} | {t.method} | `{rel}` | {len(t.rows)} | "
            f"{_fmt(t.final(report.metric, report.last_n))} |"
        )
    if report.notes:
        out += ["", "## Notes", ""] + [f"- {n}" for n in report.notes]
    return "\n".join(out) + "\n"


def make_report(
    results_dir: str | os.PathLike[str],
    out_dir: str | os.PathLike[str] | None = None,
    metric: str = DEFAULT_METRIC,
    x: str = DEFAULT_X,
    last_n: int = 1,
    group_by: str | None = None,
    columns: Sequence[str] | None = None,
) -> Path:
    """Write report.md, summary.json and curves_<env>.png; return the report.md path.

    Raises ValueError for a missing directory, no results, or a metric no trial reports.
    """
    root = Path(results_dir).expanduser()
    report = summarize(root, metric, x, last_n, group_by, columns)
    out = Path(out_dir).expanduser() if out_dir is not None else root / "report"
    out.mkdir(parents=True, exist_ok=True)
    plots: dict[str, str] = {}
    for env in sorted({g.env for g in report.groups}):
        name = f"curves_{_slug(env)}.png"
        plot_env(report, env, out / name)
        plots[env] = name
    summary = {
        "metric": report.metric,
        "x": report.x,
        "last_n": report.last_n,
        "groups": [
            {
                "env": g.env,
                "method": g.method,
                "n": g.n,
                "mean": g.mean,
                "std": g.std,
                "ci95": [g.ci_low, g.ci_high],
                "iqm": g.iqm,
                "env_steps": g.env_steps,
                "finals": g.finals,
                "extra": {k: list(v) for k, v in g.extra.items()},
            }
            for g in report.groups
        ],
        "notes": report.notes,
    }
    _atomic_write(
        out / "summary.json",
        (json.dumps(_jsonable(summary), indent=2, allow_nan=False) + "\n").encode(),
    )
    md = out / "report.md"
    _atomic_write(md, render_markdown(report, root, plots).encode())
    return md


# --------------------------------------------------------------------------- CLI


def _columns(value: str) -> list[str]:
    return [c.strip() for c in value.split(",") if c.strip()]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add `rllib report` arguments to `parser` (a subparser of the `rllib` command)."""
    parser.add_argument(
        "results_dir",
        metavar="RESULTS_DIR",
        help="folder with Tune results (searched recursively for result.json)",
    )
    parser.add_argument(
        "--out", metavar="DIR", default=None, help="output folder (default: RESULTS_DIR/report)"
    )
    parser.add_argument(
        "--metric",
        default=DEFAULT_METRIC,
        help=f"result key to compare, '/'-separated (default: {DEFAULT_METRIC})",
    )
    parser.add_argument(
        "--x", default=DEFAULT_X, help=f"x axis of the learning curves (default: {DEFAULT_X})"
    )
    parser.add_argument(
        "--last-n",
        type=int,
        default=1,
        metavar="N",
        help="final value = mean of each trial's last N iterations (default: 1)",
    )
    parser.add_argument(
        "--group-by",
        metavar="KEY",
        default=None,
        help="group trials by this dotted params key (e.g. asor.lambda_) "
        "instead of the method name",
    )
    parser.add_argument(
        "--columns",
        metavar="KEY[,KEY]",
        type=_columns,
        action="extend",
        default=None,
        help="extra final-metric columns, or 'all' for every race/... and asor/... key "
        "(default: race/... and asor/{disc_acc,real_fraction,aug_reward_mean,lambda})",
    )


def run(args: argparse.Namespace) -> int:
    """Run `rllib report`; 0 on success, 2 (one line on stderr) on bad input."""
    try:
        md = make_report(
            args.results_dir,
            args.out,
            metric=args.metric,
            x=args.x,
            last_n=args.last_n,
            group_by=args.group_by,
            columns=args.columns,
        )
    except ValueError as e:
        print(f"rllib report: error: {e}", file=sys.stderr)
        return 2
    except OSError as e:
        print(f"rllib report: error: {e}", file=sys.stderr)
        return 1
    print(md)
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Stand-alone entry: ``python -m rllib_asor.cli.report RESULTS_DIR``."""
    parser = argparse.ArgumentParser(prog="rllib report", description=__doc__.splitlines()[0])
    add_arguments(parser)
    return run(parser.parse_args(argv))


if __name__ == "__main__":
    raise SystemExit(main())
