"""One-off study script: race_speed's measurement of one layout, with the
driver's `LearnerGroup.update` and the wait for the runner's batch timed (means per iteration).

    cd <tree> && LAYOUT=overlap1 PYTHONPATH=. OMP_NUM_THREADS=1 \
        python studies/race_speed/scripts/overlap_parts.py
"""

# ruff: noqa: E402
import argparse
import json
import sys
import time

sys.argv = [sys.argv[0]]
import benchmarks.race_speed as rs
from rllib_asor.algorithms.ppo import overlap

T = {"collect": 0.0, "update": 0.0, "n": 0}
orig_collect = overlap.OverlappedPPO._collect


def collect(self):
    t = time.perf_counter()
    r = orig_collect(self)
    T["collect"] += time.perf_counter() - t
    return r


overlap.OverlappedPPO._collect = collect
import ray.rllib.core.learner.learner_group as lg

orig_update = lg.LearnerGroup.update


def update(self, *a, **k):
    t = time.perf_counter()
    r = orig_update(self, *a, **k)
    T["update"] += time.perf_counter() - t
    T["n"] += 1
    return r


lg.LearnerGroup.update = update
import os

ns = argparse.Namespace(
    layout=os.environ["LAYOUT"],
    net="small",
    iters=8,
    warmup=24,
    learner_threads=1,
    no_asor=False,
    profile=False,
)
res = rs.measure_here(ns)
print(
    json.dumps({k: res[k] for k in ("env_steps_per_s", "wall_s")}),
    {k: round(v / T["n"], 4) if k != "n" else v for k, v in T.items()},
)
