"""`rllib train`: validate every experiment, start/join Ray, run each with Ray Tune."""

from __future__ import annotations

import argparse
import os
import sys
from typing import Any

from rllib_asor.cli import experiment, manifest
from rllib_asor.cli.errors import Problems, UsageError
from rllib_asor.report.results import RUN_KEY, SMOKE_KEY

DEFAULT_STORAGE = "~/ray_results"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `rllib train [file PATH]`."""
    parser.add_argument(
        "source",
        nargs="*",
        metavar="file PATH",
        help="'file PATH' of a YAML experiment file (old RLlib format)",
    )
    parser.add_argument("-f", "--config-file", help="same as 'file PATH'")
    parser.add_argument("--run", help="algorithm (PPO, SAC, ...) when no file is given")
    parser.add_argument("--env", help="env id when no file is given")
    parser.add_argument("--config", help="JSON algorithm config when no file is given")
    parser.add_argument("--name", help="experiment name when no file is given")
    parser.add_argument(
        "--test",
        action="store_true",
        help="tiny run: 2 env runners at 0.5 CPU, batch 256, 2 iterations",
    )
    parser.add_argument("--num-env-runners", type=int, help="override num_env_runners")
    parser.add_argument(
        "--stop",
        action="append",
        metavar="KEY=VALUE",
        help="stop criterion (repeatable); legacy names are translated",
    )
    parser.add_argument("--storage-path", help=f"results root (default {DEFAULT_STORAGE})")
    parser.add_argument(
        "--resume",
        action="store_true",
        help="resume the experiment found under the storage path (a rerun of the same "
        "experiment resumes anyway; this one refuses to start a new run)",
    )
    parser.add_argument(
        "--fresh",
        action="store_true",
        help="start over: a folder holding this experiment's name is renamed NAME.replaced-TIME",
    )
    parser.add_argument("--address", help="join a running Ray cluster (HOST:PORT or auto)")
    parser.add_argument(
        "--dry-run",
        "--print-config",
        action="store_true",
        dest="dry_run",
        help="translate and validate only (no Ray): print the warnings and the new-stack YAML",
    )
    parser.add_argument("--checkpoint-freq", type=int, help="checkpoint every N iterations")
    parser.add_argument(
        "--keep-checkpoints",
        type=int,
        help=f"checkpoints to keep per trial (default {experiment.DEFAULT_NUM_TO_KEEP})",
    )


def load_experiments(
    args: argparse.Namespace, problems: Problems | None = None
) -> list[experiment.Experiment]:
    """Experiments from `file PATH` / `-f PATH` or from `--run/--env/--config` (with
    `problems`: a file's experiments that do not parse are kept there, the others returned)."""
    path = args.config_file
    if args.source:
        if len(args.source) == 1 and args.source[0].endswith((".yaml", ".yml")):
            path = args.source[0]  # `rllib train X.yaml`: what `rllib train file X.yaml` means
        elif args.source[0] != "file" or len(args.source) != 2:
            given = " ".join(args.source)
            raise UsageError(
                f"{given!r} is invalid: allowed 'file PATH' (did you mean "
                f"'rllib train file {args.source[-1]}'?)"
            )
        else:
            path = args.source[1]
    if path:
        if args.run or args.env or args.config:
            raise UsageError("give either 'file PATH' or --run/--env/--config, not both")
        exps = experiment.load_file(path, problems)
        if args.name and len(exps) == 1:
            exps[0].name = args.name
        return exps
    if not args.run or not args.env:
        raise UsageError(
            "missing input: allowed 'file PATH' or --run ALGO --env ID [--config JSON]"
        )
    return [experiment.from_flags(args.run, args.env, args.config, args.name)]


def storage_path(args: argparse.Namespace, exp: experiment.Experiment) -> str:
    path = args.storage_path or exp.storage_path or DEFAULT_STORAGE
    if "://" in path:
        return path
    return os.path.abspath(os.path.expanduser(path))


def _trainable(exp: experiment.Experiment) -> Any:
    if exp.asor is None:
        return experiment.algorithm_class(exp)
    from rllib_asor.rllib.trainable import asor_trainable

    return asor_trainable(exp.run)


def run(args: argparse.Namespace) -> int:
    """Validate all experiments first (exit 2 on bad input), then train each (exit 1 on failure)."""
    failed = sum(print_summary(exp, results) for exp, results in train(args))
    return 1 if failed else 0


def train(args: argparse.Namespace) -> list[tuple[experiment.Experiment, Any]]:
    """Validate every experiment (UsageError on bad input), run each with Tune and stop the
    Ray this call started (so no worker output follows); each experiment's ResultGrid."""
    stop = experiment.parse_stop_flags(args.stop)
    if args.resume and (args.fresh or args.test):
        raise UsageError(
            "--resume continues a real run; allowed without --fresh and --test (smoke runs "
            "start over)"
        )
    from rllib_asor.cli.cluster import check_local_gpus

    problems = Problems()
    exps = load_experiments(args, problems)
    configs = []
    for exp in exps:
        with problems.check():  # every problem of every experiment at once
            experiment.check_file(exp)  # as written, before --test/--stop replace anything
        with problems.check():  # what the run adds (a missing stop, the env), once each
            experiment.apply_overrides(
                exp,
                test=args.test,
                num_env_runners=args.num_env_runners,
                stop=stop,
                checkpoint_freq=args.checkpoint_freq,
                keep_checkpoints=args.keep_checkpoints,
            )
            configs.append(experiment.validate(exp))
            if not args.address and not getattr(args, "dry_run", False):
                check_local_gpus(exp, configs[-1])  # a local Ray has this machine's GPUs only
    problems.raise_any()
    if getattr(args, "dry_run", False):
        from rllib_asor.cli.dry_run import print_experiments

        print_experiments(exps)
        return []
    from rllib_asor.cli.cluster import probe, start_ray

    if args.address:
        probe(args.address)  # fail fast (exit 2) before anything else is printed
    for exp in exps:
        if args.test and not args.name:
            exp.name += manifest.SMOKE_SUFFIX  # smoke runs never share a folder with real runs
    resumes = [_prepare_folder(exp, args) for exp in exps]
    for exp in exps:
        for warning in dict.fromkeys(exp.warnings):
            print(f"rllib: warning: {warning}", file=sys.stderr)
    # Tune's CLIReporter (our live table) is used only with the old output engine.
    os.environ["RAY_AIR_NEW_OUTPUT"] = "0"
    started = start_ray(args.address, max(experiment.required_cpus(c) for c in configs))
    try:
        return [
            (exp, _fit(exp, cfg, args, resume))
            for exp, cfg, resume in zip(exps, configs, resumes, strict=True)
        ]
    finally:
        if started:
            import ray

            ray.shutdown()


def _max_concurrent(algo_config: Any) -> int | None:
    """Offline runs: as many trials at once as the cluster has CPUs for, Ray Data included
    (Tune counts only the trials' own reservations and would start trials whose readers then
    wait forever). None (Tune's rule) otherwise."""
    import ray

    if not experiment.offline_data_cpus(algo_config):
        return None
    cpus = float(ray.cluster_resources().get("CPU", 1.0))
    return max(1, int(cpus // experiment.required_cpus(algo_config)))


def _prepare_folder(exp: experiment.Experiment, args: argparse.Namespace) -> bool:
    """Check the experiment folder against what would run now (`rllib_asor.cli.manifest`) and
    record it; True when the Tune experiment in it is resumed."""
    from ray import tune

    path = os.path.join(storage_path(args, exp), exp.name)
    if "://" in path:  # remote storage: Tune's own resume, unchecked
        if args.resume and not tune.Tuner.can_restore(path):
            raise UsageError(f"no previous run to resume at {path}", key="--resume")
        return bool(args.resume)
    if args.resume and not tune.Tuner.can_restore(path):
        raise UsageError(
            f"no previous run to resume at {path} (train once without --resume)", key="--resume"
        )
    wanted = manifest.describe(exp, smoke=args.test)
    if args.resume and manifest.read(path) is None:
        print(f"rllib: warning: {path} holds no record of what was run; resumed unchecked, as "
              "--resume asks", file=sys.stderr)  # fmt: skip
        manifest.lock(path)
        manifest.write(path, wanted)
        return True
    _, same = manifest.prepare(path, wanted, fresh=args.fresh, smoke=args.test)
    return same and tune.Tuner.can_restore(path)


def _fit(
    exp: experiment.Experiment, algo_config: Any, args: argparse.Namespace, resume: bool
) -> Any:
    """Run one experiment with Tune; its ResultGrid."""
    from ray import tune

    from rllib_asor.cli.progress import LineReporter
    from rllib_asor.registry import env_names

    env_names.register_env(exp.env)
    trainable = _trainable(exp)
    space = experiment.param_space(exp, algo_config)
    space[RUN_KEY] = exp.run  # the method label of `rllib report` (rllib_asor.report.results)
    if args.test:
        space[SMOKE_KEY] = True  # `rllib compare` gives smoke runs no verdict
    root = storage_path(args, exp)
    print(
        f"rllib: {exp.name}: {exp.run} on {exp.env}, {exp.num_trials} trial(s), "
        f"stop {exp.stop}, results in {os.path.join(root, exp.name)}",
        flush=True,
    )
    if resume:
        print(
            f"rllib: {exp.name}: resuming (finished trials are kept; --fresh starts over)",
            flush=True,
        )
        restore = dict(trainable=trainable, resume_unfinished=True, resume_errored=True)
        path = os.path.join(root, exp.name)
        try:
            tuner = tune.Tuner.restore(path, param_space=space, **restore)
        except ValueError as e:  # Tune wants the original keys: a run from before RUN_KEY
            if "param_space" not in str(e):
                raise
            del space[RUN_KEY]
            tuner = tune.Tuner.restore(path, param_space=space, **restore)
    else:
        run_config = tune.RunConfig(
            name=exp.name,
            storage_path=root,
            stop=exp.stop or None,
            checkpoint_config=tune.CheckpointConfig(**experiment.checkpoint_kwargs(exp)),
            progress_reporter=LineReporter(exp.stop),
            verbose=1,
        )
        tuner = tune.Tuner(
            trainable,
            param_space=space,
            run_config=run_config,
            tune_config=tune.TuneConfig(
                num_samples=exp.num_samples, max_concurrent_trials=_max_concurrent(algo_config)
            ),
        )
    return tuner.fit()


def print_summary(exp: experiment.Experiment, results: Any) -> int:
    """One line per trial; the number of errored or unfinished trials."""
    from rllib_asor.cli.progress import NO_RETURN, finite

    print(f"rllib: {exp.name}: {len(results)} trial(s), {len(results.errors)} errored")
    for result in results:
        m = result.metrics or {}
        ret = (m.get("env_runners") or {}).get("episode_return_mean")
        steps = m.get("num_env_steps_sampled_lifetime")
        ckpt = result.checkpoint.path if result.checkpoint else None
        status = "ERROR" if result.error else "OK" if m.get("done") else "STOPPED"
        ret_s = f"{ret:.2f}" if finite(ret) else NO_RETURN  # never nan
        print(
            f"  {status} iter={m.get('training_iteration')} env_steps={steps} "
            f"return_mean={ret_s} checkpoint={ckpt}"
        )
        if result.error:
            first = str(result.error).strip().splitlines()
            print(f"    error: {first[-1] if first else type(result.error).__name__}")
    unfinished = [r for r in results if not r.error and not (r.metrics or {}).get("done")]
    if unfinished:
        print(
            f"rllib: {exp.name}: {len(unfinished)} trial(s) stopped before their stop criteria "
            "(interrupted?); continue with --resume",
            file=sys.stderr,
        )
    return len(results.errors) + len(unfinished)
