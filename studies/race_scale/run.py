"""Race: the many-runner setting (ppo-asor-scale.yaml) against today's example (ppo-asor.yaml),
and (studies/race_scale_steps) the many-runner setting with more policy updates per env step,
and (studies/race_scale_budget) the many-runner setting at its own 2M-env-step stop, and
(studies/race_scale_decline) that setting with one thing changed mid-run (SWITCHES), and
(studies/race_scale_2m) today's example at its own 2M-env-step stop, and
(studies/race_scale_rollout_2m) the 32-step rollouts at that stop.

Each run trains one YAML as written (its env runners, batch, minibatch, Learner device), seed
`s` (the algorithm's and ASOR's), until `--steps` env steps, then evaluates its stochastic
policy on 3 unseen courses per map (`rllib_asor.race.evaluation`, as studies/race_250k) and
writes OUT/runs/<method>-<seed>.json.gz (`eval.per_map.*.success` is the rule's metric; `curve`
and, since studies/race_scale_decline, `trace` hold each iteration's training success and
learning statistics). A rerun skips the runs that exist; an unfinished run starts again. Runs
go to Ray as tasks, as many at once as the node's CPUs and GPUs allow (a scale run needs 16
CPUs and the GPU).

    python studies/race_scale/run.py --seeds 20 --steps 500000 --layout cpu --out studies/race_scale
    python studies/race_scale/run.py --methods rollout epochs --seeds 20 --steps 500000 \
        --layout cpu --out studies/race_scale_steps
    python studies/race_scale/run.py --seeds 1 --steps 2048 --layout cpu --out /tmp/race_scale  # smoke

`--layout cpu` (the study's layout since its amendment, README.md; recorded in each run file and
never mixed with `asis`): the Learner on the CPU, sampling in the run's process with the YAML's
total number of envs (the same rollouts, batch, minibatch and epochs), one CPU per run.
"""

from __future__ import annotations

import argparse
import numbers
import os
import sys
import time
from pathlib import Path
from typing import Any

from studies.lib.common import round_floats
from studies.lib.run_files import existing, read_run, run_file, write_run

ROOT = Path(__file__).resolve().parents[2]
TODAY, SCALE = (
    ROOT / "tuned_examples/race/ppo-asor.yaml",
    ROOT / "tuned_examples/race/ppo-asor-scale.yaml",
)
METHODS: dict[str, tuple[Path, dict[str, int]]] = {
    "today": (TODAY, {}),
    "scale": (SCALE, {}),
    # studies/race_scale_steps: the scale file with more policy updates per env step
    "rollout": (SCALE, {"train_batch_size": 3584, "minibatch_size": 896}),  # 32-step rollouts
    "epochs": (SCALE, {"minibatch_size": 1024, "num_epochs": 8}),  # 4x the gradient steps
    # studies/race_scale_budget: the scale file as written, run to its own 2M stop (--steps)
    "scale-2m": (SCALE, {}),
    # studies/race_scale_decline: the scale file as written, one thing changed mid-run (SWITCHES)
    "scale-2m-asor-off": (SCALE, {}),
    "scale-2m-lr-low": (SCALE, {}),
    "scale-2m-asor-never": (SCALE, {}),
    # studies/race_scale_2m: today's file as written, run to its own 2M stop (--steps)
    "today-2m": (TODAY, {}),
    # studies/race_scale_rollout_2m: race_scale_steps' `rollout` run to the files' 2M stop
    "rollout-2m": (SCALE, {"train_batch_size": 3584, "minibatch_size": 896}),
}
"""Each method: its YAML and the `.training()` settings that replace the YAML's."""
LOW_LR = 3e-4


def _asor_off(learner: Any) -> None:
    """λ = 0 from now on: ASOR's networks still train, its bonus is 0."""
    piece = learner._asor_piece
    piece.asor = piece.asor.model_copy(update={"lambda_": 0.0})
    for module_id in piece.module_ids.values():
        learner.module[module_id].unwrapped().trainer.cfg = piece.asor


def _lr_low(learner: Any) -> None:
    """The policy's learning rate fixed at LOW_LR (ppo-asor.yaml's end value) from now on."""
    from ray.rllib.utils.schedules.scheduler import Scheduler

    for optimizer in list(learner._optimizer_lr_schedules):
        learner._optimizer_lr_schedules[optimizer] = Scheduler(
            fixed_value_or_schedule=LOW_LR, framework="torch", device=learner._device
        )


SWITCHES = {
    "scale-2m-asor-off": (450_000, _asor_off),
    "scale-2m-lr-low": (450_000, _lr_low),
    # after the first iteration: λ is still 0 there (ASOR's warm-up), so the run is
    # `scale-2m`'s until the bonus would first act
    "scale-2m-asor-never": (0, _asor_off),
}
"""Method → (env steps, what changes in its Learner after the first iteration that reaches
them). A `--layout cpu` run is deterministic, so up to there it is the same run as `scale-2m`
of the same seed (study-only surgery on RLlib's and ASOR's private attributes, to test a cause
from the same state)."""
EVAL_EPISODES = 3
MAX_EPISODE_STEPS = 1000


def build_config(method: str, seed: int, steps: int, layout: str) -> Any:
    """The YAML's AlgorithmConfig with ASOR, seeded; `layout="cpu"` moves it onto one CPU
    process (same total envs, same batch, minibatch and epochs)."""
    import rllib_asor
    from rllib_asor.cli import experiment

    yaml, overrides = METHODS[method]
    [exp] = experiment.load_file(str(yaml))
    config = experiment.validate(exp)
    config = config.debugging(seed=seed)
    if overrides:
        config = config.training(**overrides)
    if layout == "cpu":
        envs = max(1, config.num_env_runners) * config.num_envs_per_env_runner
        config = config.env_runners(num_env_runners=0, num_envs_per_env_runner=envs).learners(
            num_learners=0, num_gpus_per_learner=0
        )
    return rllib_asor.with_asor(config, **{**(exp.asor or {}), "seed": seed})


TRACE_EVERY = 14_336
"""A trace row is kept once at least this many env steps passed since the last one (one scale
iteration): every iteration of the scale file, every 14th of today's 1,024-step ones."""
TRACED = ("learners/default_policy", "learners/asor_disc.default_policy", "race")
"""Result sections kept per iteration in a run's `trace` (the policy's and ASOR's learning
statistics, the race's training metrics): what a run's learning curve is read against."""


def traced(result: dict[str, Any]) -> dict[str, float]:
    """The numbers of `result`'s TRACED sections, flat ("race/success_rate": 0.5)."""
    out = {}
    for section in TRACED:
        node: Any = result
        for key in section.split("/"):
            node = node.get(key) if isinstance(node, dict) else None
        for key, value in (node if isinstance(node, dict) else {}).items():
            if isinstance(value, numbers.Real) and not isinstance(value, bool):
                out[f"{section}/{key}"] = float(value)
    return out


def trace_due(steps: int, trace: list[dict[str, float]]) -> bool:
    """Whether the iteration that ended at `steps` env steps gets a trace row (TRACE_EVERY)."""
    return not trace or steps - trace[-1].get("env_steps", 0) >= TRACE_EVERY


def run_one(spec: dict[str, Any]) -> dict[str, Any]:
    """Train one (method, seed) to the budget, evaluate, return the run record."""
    import torch

    from rllib_asor.evaluation.rollout import module_policy
    from rllib_asor.race.config import register_race_envs
    from rllib_asor.race.evaluation import evaluate

    torch.set_num_threads(1)
    register_race_envs()
    algo = build_config(spec["method"], spec["seed"], spec["steps"], spec["layout"]).build_algo()
    at, switch = SWITCHES.get(spec["method"], (None, None))
    curve, trace, steps, switched_at, t0 = [], [], 0, None, time.time()
    while steps < spec["steps"]:
        result = algo.train()
        steps = int(result["num_env_steps_sampled_lifetime"])
        race = result.get("race", {})
        curve.append([steps, race.get("success_rate", float("nan")), time.time() - t0])
        if trace_due(steps, trace):
            trace.append({"env_steps": steps, **traced(result)})
        if switch is not None and steps >= at and switched_at is None:
            algo.learner_group.foreach_learner(switch)
            switched_at = steps
    train_s = time.time() - t0
    ev = evaluate(module_policy(algo.get_module(), explore=True), EVAL_EPISODES, MAX_EPISODE_STEPS)
    algo.stop()
    return {
        "method": spec["method"],
        "seed": spec["seed"],
        "layout": spec["layout"],
        "budget": spec["steps"],
        "steps": steps,
        "train_wall_s": train_s,
        "eval": ev,
        # per-iteration records that no rule reads at full precision: 6 significant digits
        "curve": round_floats(curve),
        "trace": round_floats(trace),
        **({"switched_at": switched_at} if switch is not None else {}),
    }


def resources(method: str, layout: str) -> dict[str, float]:
    """What one run's Ray task holds (its env runners ask for their own CPUs)."""
    if layout == "cpu":
        return {"num_cpus": 1, "num_gpus": 0}
    return {"num_cpus": 1, "num_gpus": 1 if METHODS[method][0] == SCALE else 0}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument(
        "--seed-list", type=int, nargs="+", help="these seeds, in this order (instead of --seeds)"
    )
    parser.add_argument("--steps", type=int, default=500_000, help="env-step budget per run")
    parser.add_argument("--methods", nargs="+", default=list(METHODS), choices=list(METHODS))
    parser.add_argument("--layout", choices=["asis", "cpu"], default="asis")
    parser.add_argument(
        "--at-once",
        type=int,
        help="runs in flight at most, started in the order of the seeds (default: all "
        "submitted at once, started in Ray's order)",
    )
    parser.add_argument("--out", default="studies/race_scale")
    args = parser.parse_args(argv)
    if args.seeds < 1 or args.steps < 1 or (args.at_once is not None and args.at_once < 1):
        parser.error(
            f"--seeds {args.seeds} / --steps {args.steps} / --at-once {args.at_once}: "
            "allowed integers ≥ 1"
        )
    runs = Path(args.out).resolve() / "runs"
    runs.mkdir(parents=True, exist_ok=True)
    specs = []
    seeds = args.seed_list or range(args.first_seed, args.first_seed + args.seeds)
    for seed in seeds:
        for method in args.methods:
            path = existing(run_file(runs, f"{method}-{seed}"))
            if path:
                have = read_run(path)
                if (have.get("layout"), have.get("budget")) != (args.layout, args.steps):
                    parser.error(
                        f"{path} was made with layout {have.get('layout')!r}, budget "
                        f"{have.get('budget')}: allowed the same --layout and --steps, or another --out"
                    )
                continue
            specs.append(
                {"method": method, "seed": seed, "steps": args.steps, "layout": args.layout}
            )
    if not specs:
        print("every run exists")
        return 0
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    import ray

    ray.init(include_dashboard=False, log_to_driver=False, configure_logging=False)
    sys.path.insert(0, str(ROOT))
    # max_calls=1: each run in a fresh worker process, which gives its memory back when the run
    # ends (a 2M-step run holds about 4.7 GB, and a reused worker kept growing from there)
    # Ray starts queued tasks in no set order, so with --at-once only that many are submitted
    # and the next spec goes in when one ends: the runs start in the order of `specs`
    queue, at_once, pending = list(specs), args.at_once or len(specs), {}
    while queue or pending:
        while queue and len(pending) < at_once:
            s = queue.pop(0)
            task = ray.remote(max_calls=1, **resources(s["method"], s["layout"]))(run_one)
            pending[task.remote(s)] = s
        [done], _ = ray.wait(list(pending), num_returns=1)
        spec = pending.pop(done)
        record = ray.get(done)
        write_run(run_file(runs, f"{spec['method']}-{spec['seed']}"), record)
        success = record["eval"]["mean"]["success"]
        print(
            f"{spec['method']}-{spec['seed']}: success {success:.2f}, "
            f"{record['steps']} env steps in {record['train_wall_s']:.0f} s",
            flush=True,
        )
    ray.shutdown()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
