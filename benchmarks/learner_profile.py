"""Where the race PPO(+ASOR) Learner's time goes per minibatch: cProfile, torch op counts, host syncs.

Builds the Learner in-process exactly as `benchmarks.scaling --parts learner` does (race_net,
recorded race episodes, `learner.update(episodes=...)`), runs one warm-up update and then
profiles `--updates` updates three ways, each normalised per minibatch:

- `timing`: wall and CPU time split into the Learner connector (per update: episodes → train
  batch, GAE, ASOR's piece), RLlib's `_update` per minibatch (forward, loss, backward,
  optimizer) and the rest of `learner.update` per minibatch (minibatch iterator, metrics).
- `cprofile`: Python functions by own CPU time (tottime) and by inclusive CPU time (cumtime),
  in ms per minibatch; the per-update Learner connector (episodes → batch, GAE, ASOR's piece) shows
  as `_make_batch_if_necessary` and is spread over the update's minibatches.
- `torch`: `torch.profiler` (with `--device cuda` also the GPU's own kernel time per minibatch:
  far below the wall time means the GPU waits on the host, i.e. per-call overhead).
- `ops`: aten operators that reach the dispatcher (forward, backward, optimizer, metrics:
  each is at least one kernel launch on a GPU), by name and count.
- `syncs`: operations that stall a CUDA stream when the tensors live on a GPU: reading a
  tensor on the host (`.item()`, `float(t)`, `bool(t)`, `if t:`: `aten::_local_scalar_dense`),
  `.tolist()`/`.numpy()`/`.cpu()` of a tensor, boolean-mask indexing and `nonzero` (the output
  size is only known on the host), and `torch.tensor(host data)` / `.to(device)` (a blocking
  copy from host memory). Counted on the CPU by a dispatch mode and a function mode,
  each with the first call site outside torch.

    OMP_NUM_THREADS=1 nice python -m benchmarks.learner_profile --algos ppo,asor
    python -m benchmarks.learner_profile --what syncs --algos ppo --minibatch 2048 --runners 2

Episodes are recorded once (as `benchmarks.scaling` does) and cached in `--episodes`.
"""

from __future__ import annotations

import argparse
import collections
import cProfile
import io
import os
import pickle
import pstats
import sys
import time
import traceback
from pathlib import Path
from typing import Any

WHAT = ("timing", "cprofile", "ops", "syncs", "torch")
# Ops whose result size or value the host must read (a stream sync when the input is on a GPU).
SYNC_OPS = {
    "aten::_local_scalar_dense": "read a value on the host (.item/float/int/bool/if)",
    "aten::nonzero": "nonzero / boolean-mask indexing (size known only on the host)",
    "aten::masked_select": "masked_select (size known only on the host)",
    "aten::unique": "unique",
    "aten::_unique2": "unique",
    "aten::repeat_interleave": "repeat_interleave with tensor repeats",
    # torch.tensor(host data, device=...): a blocking host→device copy on a GPU (PyTorch syncs
    # the stream after a copy from pageable memory).
    "aten::lift_fresh": "torch.tensor(host data)",
}
SYNC_METHODS = ("cpu", "numpy", "tolist")
# Ops that only make a new view (or record a profiler range): CPU dispatch work, no kernel.
VIEW_OPS = {
    "aten::" + name
    for name in (
        "detach", "t", "view", "_unsafe_view", "slice", "transpose", "permute", "unsqueeze",
        "squeeze", "expand", "select", "as_strided", "alias", "unbind", "split", "narrow",
        "split_with_sizes", "lift_fresh", "_record_function_enter_new", "_record_function_exit",
        "_reshape_alias", "unflatten", "chunk", "_local_scalar_dense",
    )
}  # fmt: skip


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--algos", default="ppo,asor", help="comma list of ppo, asor")
    p.add_argument("--what", default=",".join(WHAT), help="comma list of " + ",".join(WHAT))
    p.add_argument("--runners", type=int, default=1, help="recorded batches per update")
    p.add_argument("--minibatch", type=int, default=256)
    p.add_argument("--epochs", type=int, default=4)
    p.add_argument("--updates", type=int, default=2, help="profiled updates (after 1 warm-up)")
    p.add_argument("--top", type=int, default=30, help="rows per table")
    p.add_argument("--device", default="cpu", help="the Learner's device: cpu or cuda")
    p.add_argument("--model-config", default="{}", help="race_net settings (JSON)")
    p.add_argument(
        "--episodes",
        default="/tmp/race_learner_profile_episodes.pkl",
        help="cache of the recorded episodes (made when missing)",
    )
    return p


def scaling_args(args: argparse.Namespace) -> argparse.Namespace:
    """The `benchmarks.scaling` settings these profiles share with its Learner part."""
    import json

    from benchmarks import scaling

    argv = [
        "--minibatch", str(args.minibatch), "--epochs", str(args.epochs),
        "--device", args.device, "--model-config", args.model_config,
        "--record-batches", str(max(2, args.runners + 1)),
    ]  # fmt: skip
    ns = scaling.settle(scaling.build_parser().parse_args(argv))
    ns.model_config = json.loads(args.model_config)
    return ns


def recorded_episodes(args: argparse.Namespace, ns: argparse.Namespace) -> list[list[Any]]:
    from benchmarks import scaling

    path = Path(args.episodes)
    if path.exists():
        recorded = pickle.loads(path.read_bytes())
        if len(recorded) >= ns.record_batches:
            return recorded
    recorded = scaling.record_episodes(ns)
    path.write_bytes(pickle.dumps(recorded))
    return recorded


class Run:
    """One Learner and its batches: `update(i)` trains on batch i (episodes copied before)."""

    def __init__(self, algo: str, args: argparse.Namespace) -> None:
        import torch
        from ray.rllib.utils.metrics import NUM_ENV_STEPS_SAMPLED_LIFETIME

        from benchmarks import scaling

        torch.set_num_threads(int(os.environ.get("OMP_NUM_THREADS", "1") or 1))
        torch.manual_seed(0)
        self.ns = scaling_args(args)
        self.recorded = recorded_episodes(args, self.ns)
        self.learner = scaling._build_learner(scaling.race_config(algo, self.ns, args.runners))
        self.args, self.key, self.lifetime = args, NUM_ENV_STEPS_SAMPLED_LIFETIME, 0
        self.refill()

    def refill(self) -> None:
        """Fresh copies of the batches (the Learner connector extends episodes in place)."""
        from benchmarks import scaling

        n = len(self.recorded)
        self.batches = [
            scaling.runner_batch(self.recorded, b % n, self.args.runners)
            for b in range(1 + self.args.updates)
        ]

    def update(self, b: int) -> None:
        import torch

        episodes = self.batches[b]
        self.lifetime += sum(len(e) for e in episodes)
        self.learner.update(
            episodes=episodes,
            timesteps={self.key: self.lifetime},
            num_epochs=self.args.epochs,
            minibatch_size=self.args.minibatch,
            shuffle_batch_per_epoch=True,
        )
        if self.args.device == "cuda":
            torch.cuda.synchronize()


def count_minibatches(run: Run) -> int:
    """Minibatches `learner.update` runs per update (wraps RLlib's `_update`)."""
    learner, calls = run.learner, [0]
    inner = learner._update

    def counting(*a: Any, **k: Any) -> Any:
        calls[0] += 1
        return inner(*a, **k)

    learner._update = counting
    run.update(0)  # the warm-up update
    del learner._update
    return calls[0]


def profile_timing(run: Run, minibatches: int) -> str:
    learner = run.learner
    spent: dict[str, list[float]] = {"connector": [0.0, 0.0], "update": [0.0, 0.0]}

    def timed(name: str, inner: Any) -> Any:
        def call(*a: Any, **k: Any) -> Any:
            t0, c0 = time.perf_counter(), time.process_time()
            try:
                return inner(*a, **k)
            finally:
                if run.args.device == "cuda":
                    import torch

                    torch.cuda.synchronize()
                spent[name][0] += time.perf_counter() - t0
                spent[name][1] += time.process_time() - c0

        return call

    learner._make_batch_if_necessary = timed("connector", learner._make_batch_if_necessary)
    learner._update = timed("update", learner._update)
    t0, c0 = time.perf_counter(), time.process_time()
    for b in range(1, 1 + run.args.updates):
        run.update(b)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    del learner._make_batch_if_necessary, learner._update
    n = minibatches * run.args.updates
    rest = [
        wall - spent["connector"][0] - spent["update"][0],
        cpu - spent["connector"][1] - spent["update"][1],
    ]
    out = [
        f"ms per minibatch (wall / CPU), {n} minibatches (synchronised on a GPU after each part):"
    ]
    for label, (w, c) in (
        ("all of learner.update", (wall, cpu)),
        ("Learner connector (per update, spread)", spent["connector"]),
        ("_update: forward, loss, backward, optimizer", spent["update"]),
        ("the rest: minibatch iterator, metrics, RLlib loop", rest),
    ):
        out.append(f"{1000 * w / n:8.2f} / {1000 * c / n:8.2f}  {label}")
    return "\n".join(out)


def profile_torch(run: Run, minibatches: int, top: int) -> str:
    from torch.profiler import ProfilerActivity, profile

    cuda = run.args.device == "cuda"
    activities = [ProfilerActivity.CPU] + ([ProfilerActivity.CUDA] if cuda else [])
    t0 = time.perf_counter()
    with profile(activities=activities) as prof:
        for b in range(1, 1 + run.args.updates):
            run.update(b)
    wall = time.perf_counter() - t0
    n = minibatches * run.args.updates
    events = prof.key_averages()
    out = [f"{1000 * wall / n:.1f} ms wall per minibatch under torch.profiler"]
    if cuda:
        device_us = sum(getattr(e, "self_device_time_total", 0) for e in events)
        out.append(f"GPU kernel time: {device_us / 1000 / n:.2f} ms per minibatch")
    sort = "self_cuda_time_total" if cuda else "self_cpu_time_total"
    out.append(events.table(sort_by=sort, row_limit=top))
    return "\n".join(out)


def profile_python(run: Run, minibatches: int, top: int) -> str:
    # CPU time of this process, not the wall clock: other jobs on a shared machine then add
    # little (on a GPU, time spent waiting in a sync still counts: CUDA spins).
    prof = cProfile.Profile(time.process_time)
    t0, c0 = time.perf_counter(), time.process_time()
    prof.enable()
    for b in range(1, 1 + run.args.updates):
        run.update(b)
    prof.disable()
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    n = minibatches * run.args.updates
    out = [
        f"{n} minibatches; {1000 * wall / n:.1f} ms wall, {1000 * cpu / n:.1f} ms CPU per minibatch (under cProfile)"
    ]
    stats = pstats.Stats(prof)
    rows = []
    for (file, line, name), (_cc, nc, tt, ct, _callers) in stats.stats.items():  # type: ignore[attr-defined]
        where = f"{_short(file)}:{line}({name})"
        rows.append((tt, ct, nc, where))
    for label, idx in (("tottime", 0), ("cumtime", 1)):
        out.append(f"\n-- by {label}: ms per minibatch (calls per minibatch) --")
        for r in sorted(rows, key=lambda r: -r[idx])[:top]:
            out.append(f"{1000 * r[idx] / n:8.2f} ms  {r[2] / n:7.1f}x  {r[3]}")
    return "\n".join(out)


def _short(file: str) -> str:
    for marker in ("site-packages/", "rllib_asor/", "benchmarks/"):
        if marker in file:
            return (
                file.split(marker, 1)[1]
                if marker == "site-packages/"
                else marker + file.split(marker, 1)[1]
            )
    return file


def _call_site() -> str:
    """The first frame outside torch (and this file): where a sync or op was asked for."""
    for frame in reversed(traceback.extract_stack()[:-2]):
        f = frame.filename
        if "site-packages/torch/" in f or f.endswith("learner_profile.py"):
            continue
        return f"{_short(f)}:{frame.lineno}({frame.name})"
    return "?"


def profile_ops_and_syncs(run: Run, minibatches: int, top: int, what: list[str]) -> str:
    import torch
    from torch.overrides import TorchFunctionMode
    from torch.utils._python_dispatch import TorchDispatchMode

    ops: collections.Counter[str] = collections.Counter()
    syncs: collections.Counter[tuple[str, str]] = collections.Counter()
    want_syncs = "syncs" in what

    class Ops(TorchDispatchMode):
        def __torch_dispatch__(self, func, types, args=(), kwargs=None):  # type: ignore[no-untyped-def]
            name = "aten::" + func.__name__.split(".")[0]
            ops[name] += 1
            if want_syncs and name in SYNC_OPS:
                if name != "aten::repeat_interleave" or isinstance(args[1], torch.Tensor):
                    syncs[(name, _call_site())] += 1
            elif want_syncs and name == "aten::_to_copy" and (kwargs or {}).get("device"):
                syncs[("Tensor.to(device)", _call_site())] += 1
            elif want_syncs and name in ("aten::index", "aten::index_put", "aten::index_put_"):
                masks = [
                    i for i in args[1] if isinstance(i, torch.Tensor) and i.dtype == torch.bool
                ]
                if masks:  # a boolean mask: its nonzero() runs inside the op
                    syncs[(name + "[bool mask]", _call_site())] += 1
            return func(*args, **(kwargs or {}))

    class Methods(TorchFunctionMode):
        def __torch_function__(self, func, types, args=(), kwargs=None):  # type: ignore[no-untyped-def]
            name = getattr(func, "__name__", "")
            if name in SYNC_METHODS:
                syncs[(f"Tensor.{name}()", _call_site())] += 1
            return func(*args, **(kwargs or {}))

    t0 = time.perf_counter()
    with Ops(), Methods():
        for b in range(1, 1 + run.args.updates):
            run.update(b)
    n = minibatches * run.args.updates
    out = []
    if "ops" in what:
        total = sum(ops.values())
        kernels = sum(c for name, c in ops.items() if name not in VIEW_OPS)
        out.append(
            f"aten ops per minibatch: {total / n:.0f}, of them {kernels / n:.0f} that launch a "
            f"kernel on a GPU (the rest make views); {time.perf_counter() - t0:.0f} s under the modes"
        )
        for name, c in ops.most_common(top):
            out.append(f"{c / n:8.1f}  {name}")
    if want_syncs:
        total = sum(syncs.values())
        out.append(f"\nhost syncs per minibatch on a GPU: {total / n:.1f}")
        for (name, where), c in syncs.most_common(top):
            out.append(f"{c / n:8.2f}  {name:28s} {where}")
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    from benchmarks import scaling

    args = build_parser().parse_args(argv)
    try:
        algos = scaling.parse_list(args.algos, scaling.ALGOS, "--algos")
        what = scaling.parse_list(args.what, WHAT, "--what")
        for key in ("runners", "minibatch", "epochs", "updates"):
            if getattr(args, key) < 1:
                raise ValueError(f"--{key} {getattr(args, key)} is invalid: allowed ≥ 1")
        scaling.check_device(args.device)
    except ValueError as e:
        print(f"learner_profile: {e}", file=sys.stderr)
        return 2
    for algo in algos:
        run = Run(algo, args)
        per_update = count_minibatches(run)
        rows = sum(len(e) for e in run.batches[0])
        print(
            f"\n==== {scaling.LABELS[algo]}: {rows} env steps per update, {per_update} minibatches "
            f"of {args.minibatch} rows per update, {args.updates} updates profiled ====",
            flush=True,
        )
        buf = io.StringIO()
        if "timing" in what:
            buf.write(profile_timing(run, per_update) + "\n\n")
            run.refill()
        if "cprofile" in what:
            buf.write(profile_python(run, per_update, args.top) + "\n\n")
            run.refill()
        if "torch" in what:
            buf.write(profile_torch(run, per_update, args.top) + "\n\n")
            run.refill()
        if "ops" in what or "syncs" in what:
            buf.write(profile_ops_and_syncs(run, per_update, args.top, what) + "\n")
        print(buf.getvalue(), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
