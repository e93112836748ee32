"""One-off study script: `runner.sample(1024)` of the race with the small
network in the driver, timed (or profiled with --profile); NORM=1 turns RLlib's action unsquash
back on.

    cd <tree> && PYTHONPATH=. OMP_NUM_THREADS=1 python studies/race_speed/scripts/sampling.py --n 8
"""

# ruff: noqa: E402, UP031
import argparse
import cProfile
import pstats
import time

import ray
import torch

p = argparse.ArgumentParser()
p.add_argument("--n", type=int, default=8)
p.add_argument("--profile", action="store_true")
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
import os

if os.environ.get("NORM"):
    config = config.environment(normalize_actions=True, clip_actions=False)
algo = config.build_algo()
runner = algo.env_runner_group.local_env_runner
for _ in range(3):
    runner.sample(num_timesteps=1024)
prof = cProfile.Profile() if a.profile else None
ts = []
for _ in range(a.n):
    if prof:
        prof.enable()
    t = time.perf_counter()
    runner.sample(num_timesteps=1024)
    ts.append(time.perf_counter() - t)
    if prof:
        prof.disable()
print("sample 1024:", " ".join("%.3f" % x for x in ts))
if prof:
    s = pstats.Stats(prof)
    s.sort_stats("cumulative").print_stats(40)
    s.sort_stats("tottime").print_stats(25)
