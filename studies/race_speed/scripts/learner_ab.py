"""One-off study script, kept so the Learner and sampling numbers of docs/studies/race_speed.md
can be re-made: the Learner update alone, race PPO+ASOR with the small
network in ASOR's steady state, one process; each variant (variants.py) trains on a deep copy
of the same sampled batch in turn.

    cd <tree> && PYTHONPATH=.:studies/race_speed/scripts OMP_NUM_THREADS=1 \
        python studies/race_speed/scripts/learner_ab.py --variants old new new+drop --n 10
"""
# ruff: noqa: E402, UP031, B007

import argparse
import statistics
import time

import ray
import torch
from ray.rllib.utils.metrics import NUM_ENV_STEPS_SAMPLED_LIFETIME

p = argparse.ArgumentParser()
p.add_argument("--warmup", type=int, default=20)
p.add_argument("--n", type=int, default=6)
p.add_argument("--variants", nargs="+", default=["base"])
p.add_argument("--profile", default="")
a = p.parse_args()
torch.set_num_threads(1)
ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
import rllib_asor.race.config as race

try:  # a tree older than studies/ kept the runner in benchmarks/
    from studies.lib.race_learning import race_config
except ImportError:
    from benchmarks.race_learning import race_config

base_config = race.race_ppo_config
net = {"cnn_channels": [8, 16], "attn_token_size": 8}
race.race_ppo_config = lambda *x, **kw: base_config(
    *x, **kw | {"model_config": (kw.get("model_config") or {}) | net}
)
ns = argparse.Namespace(
    steps=10**7, batch=1024, epochs=4, envs=16, max_episode_steps=1000, train_map=None
)
config = race_config(0, {"mode": "asor"}, ns)
algo = config.build_algo()
for _ in range(a.warmup):
    algo.train()
L = algo.learner_group._learner
runner = algo.env_runner_group.local_env_runner
import variants

times = {v: [] for v in a.variants}
prof = None
if a.profile:
    import cProfile

    prof = cProfile.Profile()
life = 30000
rows = {}
for i in range(a.n):
    eps0 = runner.sample(num_timesteps=1024)
    life += 1024
    import copy

    for v in a.variants:
        eps = copy.deepcopy(eps0)
        variants.apply(L, v)
        if prof:
            prof.enable()
        t = time.perf_counter()
        res = algo.learner_group.update(
            episodes=eps,
            timesteps={NUM_ENV_STEPS_SAMPLED_LIFETIME: life},
            num_epochs=4,
            minibatch_size=256,
            shuffle_batch_per_epoch=True,
        )
        times[v].append(time.perf_counter() - t)
        rows[v] = (
            res[0]["default_policy"]["num_module_steps_trained"]
            if isinstance(res, list)
            else res["default_policy"]["num_module_steps_trained"]
        )
        if prof:
            prof.disable()
import numpy as np

b = np.array(times[a.variants[0]])
for v, x in times.items():
    r = np.array(x) / b
    print(
        v, "ratio to first: median %.3f mean %.3f" % (np.median(r), r.mean()), "rows", rows.get(v)
    )
    print(v, "median %.3f s" % statistics.median(x), " ".join("%.3f" % y for y in x))
if prof:
    import pstats

    s = pstats.Stats(prof)
    s.sort_stats("cumulative")
    import os

    if os.environ.get("CALLEES"):
        s.print_callees(os.environ["CALLEES"])
    else:
        s.print_stats(50)
        s.sort_stats("tottime").print_stats(25)
