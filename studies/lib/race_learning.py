"""Obstacle race: PPO vs PPO+SRPO vs PPO+ASOR at an equal env-step budget (the paper's table).

Every run trains the race network (`race_net`) on the single-racer race with a map drawn per
episode from all ten maps, for the same number of env steps; then its policy is evaluated on
each of the ten maps (fixed course seeds) and the paper's table columns are reported: success
rate, trapped rate, unnecessary-jump rate, distance from cliff, goal reward, total reward.
Two reference rows use the same evaluation episodes: the scripted racer (`game_env.scripted`,
privileged, the expert) and a uniformly random policy.

    python -m studies.lib.race_learning --seeds 1 --steps 8192 --out studies/out/race_learning

Methods are named as in `studies.lib.lava_reproduction` (`name:key=value,...` over AsorConfig
fields; `ppo` = no ASOR). ASOR and SRPO see `RACE_ASOR_OBS_KEYS` unless `obs_keys` is given.
Seeds are `--first-seed` .. `--first-seed + --seeds - 1`. Each run is written to
OUT/runs/<method>-<seed>.json.gz (`studies.lib.run_files`) as soon as it finishes; existing
run files are kept (a rerun only adds what is missing; one with another `--sampling` or
`--model-config` than a kept run recorded is refused); the success rate is
`eval.per_map.<map>.success` in them (`python -m studies.lib.compare --metric
'eval.per_map.*.success'` averages over the maps); `--summarize-only` rebuilds the tables.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from rllib_asor.evaluation.rollout import module_policy
from rllib_asor.race.evaluation import COLUMNS, evaluate
from studies.lib.common import (
    round_floats,
    run_method_seed_grid,
    runs_made_otherwise,
    start_local_ray,
    write_json,
)
from studies.lib.lava_reproduction import DEFAULT_METHODS, parse_method
from studies.lib.run_files import read_runs, run_file, write_run


def model_config_arg(text: str) -> str:
    """argparse type of `--model-config`: JSON of valid race network settings, kept as text."""
    from rllib_asor.race.net import DEFAULTS, race_net_settings

    try:
        settings = json.loads(text)
        if not isinstance(settings, dict):
            raise ValueError(f"a JSON object is needed, got {type(settings).__name__}")
        if unknown := sorted(set(settings) - set(DEFAULTS)):
            raise ValueError(f"unknown keys {unknown}: allowed {sorted(DEFAULTS)}")
        race_net_settings(settings)
    except ValueError as err:  # json.JSONDecodeError is a ValueError
        raise argparse.ArgumentTypeError(f"{text!r}: {err}") from None
    return text


def run_settings(args: argparse.Namespace) -> dict[str, Any]:
    """What a run file records besides method and seed, so that a rerun into the same folder
    with other settings is refused rather than mixed in (`--model-config` as parsed JSON)."""
    model_config = getattr(args, "model_config", None)
    return {
        "sampling": getattr(args, "sampling", "local"),
        "model_config": json.loads(model_config) if model_config else {},
        "drop_bootstrap_rows": bool(getattr(args, "drop_bootstrap_rows", False)),
        "lag_correction": (
            not getattr(args, "no_lag_correction", False)
            if getattr(args, "sampling", "local") == "overlap"
            else None
        ),
    }


def race_config(seed: int, asor: dict[str, Any] | None, args: argparse.Namespace) -> Any:
    """The shared PPO config (identical for every method), plus ASOR when given."""
    import rllib_asor
    from rllib_asor.race.config import RACE_ASOR_OBS_KEYS, race_ppo_config

    config = (
        race_ppo_config(
            num_racers=1,
            map_id=getattr(args, "train_map", None),
            max_episode_steps=args.max_episode_steps,
            curriculum=json.loads(args.curriculum) if getattr(args, "curriculum", None) else None,
            model_config=run_settings(args)["model_config"] or None,
        )
        .env_runners(num_env_runners=0, num_envs_per_env_runner=args.envs)
        .training(
            lr=[[0, 1e-3], [args.steps, 3e-4]],
            gamma=0.99,
            lambda_=0.95,
            entropy_coeff=0.003,
            train_batch_size=args.batch,
            minibatch_size=256,
            num_epochs=args.epochs,
        )
        .debugging(seed=seed)
    )
    if getattr(args, "sampling", "local") == "overlap":
        from rllib_asor.algorithms.ppo.overlap import overlap_sampling

        config = overlap_sampling(
            config.env_runners(
                num_env_runners=1, num_envs_per_env_runner=args.envs, num_cpus_per_env_runner=1
            )
        )
        lcd = {**config.learner_config_dict, "lag_correction": run_settings(args)["lag_correction"]}
        config = config.learners(learner_config_dict=lcd)
    if run_settings(args)["drop_bootstrap_rows"]:
        from rllib_asor.algorithms.ppo.lean import drop_bootstrap_rows

        config = drop_bootstrap_rows(config)
    if asor is not None:
        settings = {"seed": seed, "obs_keys": list(RACE_ASOR_OBS_KEYS)} | asor
        config = rllib_asor.with_asor(config, **settings)
    return config


def random_policy(seed: int = 0) -> Any:
    import game_env

    space = game_env.action_space()
    space.seed(seed)
    return lambda batch, envs: np.stack([space.sample() for _ in envs])


def scripted_policy(envs: list[Any]) -> Any:
    """The scripted racer on each of `envs` (it reads the simulator), found for each info by
    its course (`map_id`, `course_seed`: one env each in the race's evaluation)."""
    from game_env.scripted import ScriptedRacer

    racers = {(env.sim.map_id, env.sim.course_seed): ScriptedRacer(env) for env in envs}
    if len(racers) != len(envs):
        raise ValueError("scripted_policy: two envs race the same course")

    def act(batch: dict[str, np.ndarray], infos: list[Any]) -> np.ndarray:
        return np.stack([racers[info["map_id"], info["course_seed"]].act() for info in infos])

    return act


def run_one(config: dict[str, Any]) -> dict[str, Any]:
    """Tune function trainable: train one (method, seed) to the budget, then evaluate."""
    spec = config["spec"]
    import torch
    from ray import tune

    from rllib_asor.race.config import register_race_envs

    torch.set_num_threads(1)
    register_race_envs()
    args = argparse.Namespace(**spec["args"])
    algo = race_config(spec["seed"], spec["asor"], args).build_algo()
    curve = []
    steps, t0 = 0, time.time()
    result: dict[str, Any] = {}
    while steps < args.steps:
        result = algo.train()
        steps = result["num_env_steps_sampled_lifetime"]
        ret = result["env_runners"].get("episode_return_mean", float("nan"))
        race = result.get("race", {})
        curve.append(
            [steps, ret, race.get("success_rate", float("nan")), race.get("curriculum_stage", 0)]
        )
        tune.report({"steps": steps, "episode_return_mean": ret})
    train_s = time.time() - t0
    t1 = time.time()
    ev = evaluate(
        module_policy(algo.get_module(), explore=not args.greedy),
        args.eval_episodes,
        args.max_episode_steps,
    )
    final = {
        "method": spec["method"],
        "seed": spec["seed"],
        **run_settings(args),
        "steps": steps,
        "train_wall_s": train_s,
        "eval_wall_s": time.time() - t1,
        # the per-episode records and the curve are raw data (tables read `per_map`, exact)
        "eval": {**ev, "episodes": round_floats(ev["episodes"])},
        "curve": round_floats(curve),
        "race_last": {
            k: float(v) for k, v in result.get("race", {}).items() if not isinstance(v, dict)
        },
        "asor_last": {k: float(v) for k, v in result.get("asor", {}).items()},
    }
    write_run(run_file(Path(spec["out"]) / "runs", f"{spec['method']}-{spec['seed']}"), final)
    algo.stop()
    tune.report({"steps": steps, "done": True})
    return final


def reference_rows(out: Path, args: argparse.Namespace) -> None:
    """Scripted racer and random policy on the evaluation episodes (written once)."""
    for name, policy, needs_envs in (("scripted", scripted_policy, True),
                                     ("random", random_policy(), False)):  # fmt: skip
        path = out / "reference" / f"{name}.json"
        if path.exists():
            continue
        t0 = time.time()
        ev = evaluate(policy, args.eval_episodes, args.max_episode_steps, needs_envs=needs_envs)
        write_json(path, {"method": name, "eval": ev, "eval_wall_s": time.time() - t0})


def _row(name: str, evs: list[dict[str, Any]], steps: str, n: str) -> tuple[str, dict[str, Any]]:
    """Markdown row: mean over runs of the mean over the ten maps (± std over runs)."""
    cells, summary = [], {}
    for key, _ in COLUMNS:
        per_run = np.array([np.mean([ev["per_map"][m][key] for m in ev["per_map"]]) for ev in evs])
        sd = float(per_run.std(ddof=1)) if len(per_run) > 1 else 0.0
        summary[key] = {"mean": float(per_run.mean()), "std": sd}
        cells.append(f"{per_run.mean():.3f}" + (f" ± {sd:.3f}" if len(per_run) > 1 else ""))
    return f"| {name} | {n} | {steps} | " + " | ".join(cells) + " |", summary


def summarize(out: Path, methods: list[str]) -> str:
    """Markdown tables (overall and success per map) + summary.json from the run files."""
    runs = read_runs(out / "runs")
    refs = {p.stem: json.loads(p.read_text()) for p in sorted((out / "reference").glob("*.json"))}
    head = "| policy | runs | env steps | " + " | ".join(t for _, t in COLUMNS) + " |"
    lines = [head, "|---|---|---|" + "---|" * len(COLUMNS)]
    table: dict[str, Any] = {}
    per_map_lines = [
        "| policy | " + " | ".join(f"map {m}" for m in range(10)) + " |",
        "|---|" + "---|" * 10,
    ]
    for name in methods:
        rs = [r for r in runs if r["method"] == name]
        if not rs:
            continue
        steps = str(int(np.mean([r["steps"] for r in rs])))
        line, summary = _row(name, [r["eval"] for r in rs], steps, str(len(rs)))
        summary["seeds"] = [r["seed"] for r in rs]
        summary["train_wall_s"] = [r["train_wall_s"] for r in rs]
        table[name] = summary
        lines.append(line)
        succ = [np.mean([r["eval"]["per_map"][str(m)]["success"] for r in rs]) for m in range(10)]
        per_map_lines.append(f"| {name} | " + " | ".join(f"{v:.2f}" for v in succ) + " |")
    for name in ("random", "scripted"):
        if name in refs:
            line, summary = _row(f"{name} (reference)", [refs[name]["eval"]], "–", "–")
            table[name] = summary
            lines.append(line)
            succ = [refs[name]["eval"]["per_map"][str(m)]["success"] for m in range(10)]
            per_map_lines.append(f"| {name} | " + " | ".join(f"{v:.2f}" for v in succ) + " |")
    (out / "summary.json").write_text(json.dumps(table, indent=1))
    md = "\n".join(lines) + "\n\nSuccess rate per map:\n\n" + "\n".join(per_map_lines) + "\n"
    (out / "table.md").write_text(md)
    return md


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--methods", nargs="+", default=list(DEFAULT_METHODS))
    parser.add_argument("--seeds", type=int, default=1)
    parser.add_argument("--first-seed", type=int, default=0, help="seeds FIRST..FIRST+SEEDS-1")
    parser.add_argument("--steps", type=int, default=8192, help="env steps per run")
    parser.add_argument("--batch", type=int, default=1024, help="train batch (env steps)")
    parser.add_argument("--epochs", type=int, default=4)
    parser.add_argument(
        "--envs", type=int, default=8, help="vectorised envs of the trial (or of its env runner)"
    )
    parser.add_argument("--max-episode-steps", type=int, default=1000)
    parser.add_argument(
        "--train-map",
        type=int,
        default=None,
        help="train on this one map (0..9) instead of a random map per episode; "
        "evaluation is always on all ten",
    )
    parser.add_argument(
        "--curriculum",
        default=None,
        help='a map curriculum as JSON, e.g. \'{"stages": [[2, 6], "random"], "threshold": 0.5}\' '
        "(rllib_asor.race.curriculum.MapCurriculum); evaluation is always on all ten maps",
    )
    parser.add_argument(
        "--model-config",
        type=model_config_arg,
        default=None,
        help='race network settings as JSON, e.g. \'{"cnn_channels": [8, 16], "attn_token_size": 8}\' '
        "(rllib_asor.race.net.DEFAULTS); default: the network of the tuned examples",
    )
    parser.add_argument("--eval-episodes", type=int, default=1, help="episodes per map")
    parser.add_argument("--greedy", action="store_true", help="evaluate the argmax policy")
    parser.add_argument(
        "--sampling",
        choices=["local", "overlap"],
        default="local",
        help="local: sampling in the trial (1 CPU); overlap: one env runner sampling while the "
        "Learner trains (OverlappedPPO, 2 CPUs per trial)",
    )
    parser.add_argument(
        "--no-lag-correction",
        action="store_true",
        help="--sampling overlap without the lag correction (rllib_asor.algorithms.ppo.lag)",
    )
    parser.add_argument(
        "--drop-bootstrap-rows",
        action="store_true",
        help="PPO trains without its masked bootstrap rows (rllib_asor.algorithms.ppo.lean)",
    )
    parser.add_argument(
        "--parallel",
        type=int,
        default=3,
        help="trials at once (1 CPU each, 2 with --sampling overlap)",
    )
    parser.add_argument("--out", default="studies/out/race_learning")
    parser.add_argument("--summarize-only", action="store_true")
    args = parser.parse_args(argv)
    out = Path(args.out).resolve()
    methods = [parse_method(m) for m in args.methods]
    names = [n for n, _ in methods]
    if not args.summarize_only:
        seeds = range(args.first_seed, args.first_seed + args.seeds)
        if clash := runs_made_otherwise(
            out, names, seeds, run_settings(args), defaults={"drop_bootstrap_rows": False}
        ):
            parser.error(
                f"{out}/runs holds runs made with other settings ({', '.join(clash)}): "
                "use another --out or another method name"
            )
        os.environ.setdefault("OMP_NUM_THREADS", "1")
        t0 = time.time()
        reference_rows(out, args)
        print(f"reference rows in {time.time() - t0:.0f} s", flush=True)
        cpus_per_trial = 2 if args.sampling == "overlap" else 1
        start_local_ray(args.parallel * cpus_per_trial)
        keys = (
            "steps",
            "batch",
            "epochs",
            "envs",
            "max_episode_steps",
            "eval_episodes",
            "greedy",
            "train_map",
            "curriculum",
            "sampling",
            "model_config",
        )
        shared = {k: v for k, v in vars(args).items() if k in keys}
        run_method_seed_grid(
            run_one,
            methods,
            seeds,
            shared,
            out,
            cpus_per_trial=cpus_per_trial,
        )
    md = summarize(out, names)
    print(md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
