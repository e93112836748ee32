"""Command-line options on top of a file's values: `--test`, `--stop`, runners, checkpoints."""

from __future__ import annotations

from typing import Any

from rllib_asor.cli import legacy
from rllib_asor.cli.errors import UsageError
from rllib_asor.cli.offline_inputs import tiny_test_data
from rllib_asor.cli.spec import DEFAULT_NUM_TO_KEEP, MAPLE_KEY, Experiment
from rllib_asor.registry.families import family_of

# Settings of `--test`: a tiny local run that works on 2 cores.
TEST_STOP = {"training_iteration": 2}


TEST_ENV_RUNNERS = 2


TEST_CPUS_PER_ENV_RUNNER = 0.5


TEST_BATCH = 256


TEST_MINIBATCH = 64


TEST_DATASET_ITERS = 2


TEST_PRELEARNERS = {"concurrency": 1}
"""`--test` with offline data: one OfflinePreLearner actor (RLlib starts 2; each imports RLlib)."""


TEST_MAPLE = {
    "steps_per_iteration": 5,
    "rollout_batch_size": 256,
    "model_pool_size": 2560,
    "ensemble_max_epochs": 2,
    "ensemble_cache": None,
    "evaluation_interval": 1,
    "evaluation_episodes": 1,
}
"""`--test` budget of MAPLE/MOPO (`maple:` block): a few steps, no ensemble cache."""

TEST_GARAT = {"grounding_iterations": 1, "grounding_batch_size": TEST_BATCH}
"""`--test` budget of GARAT's grounding (`garat:` block): one small iteration."""

TEST_BCO = {
    "pre_demo_steps": TEST_BATCH,
    "idm_steps": 10,
    "bc_epochs": 1,
    "evaluation_interval": 1,
    "evaluation_episodes": 1,
}
"""`--test` budget of BCO (`bco:` block): a few steps; offline it evaluates every iteration."""

TEST_SOIL = {"idm_steps": 10, "evaluation_interval": 1, "evaluation_episodes": 1}
"""`--test` budget of SOIL's inverse dynamics model (`soil:` block); offline it evaluates every
iteration."""


def parse_stop_flags(items: list[str] | None) -> dict[str, Any]:
    """`--stop KEY=VALUE` (repeatable) -> {key: number}, legacy names translated."""
    stop: dict[str, Any] = {}
    for item in items or []:
        key, sep, raw = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise UsageError(
                f"{item!r} is invalid: allowed KEY=VALUE, e.g. training_iteration=10", key="--stop"
            )
        stop[key] = _number(raw.strip())
    translated, _ = legacy.translate_stop(stop, "", "--stop ")
    return translated


def _number(raw: str) -> Any:
    """'10' -> 10, '1e5' -> 100000.0, anything else stays a string."""
    for cast in (int, float):
        try:
            return cast(raw)
        except ValueError:
            pass
    return raw


def cuda_available() -> bool:
    """Whether torch sees a CUDA device on this machine."""
    import torch

    return torch.cuda.is_available()


def apply_overrides(
    exp: Experiment,
    *,
    test: bool = False,
    num_env_runners: int | None = None,
    stop: dict[str, Any] | None = None,
    checkpoint_freq: int | None = None,
    keep_checkpoints: int | None = None,
) -> None:
    """Apply command-line options on top of the file's values (in place)."""
    cfg = exp.config
    if test:
        offline = cfg.get("input", "sampler") != "sampler"
        if offline:  # data from files: few dataset passes, the file's env runners (often 0)
            cfg["dataset_num_iters_per_learner"] = TEST_DATASET_ITERS
            cfg["map_batches_kwargs"] = {
                **(cfg.get("map_batches_kwargs") or {}),
                **TEST_PRELEARNERS,
            }
            tiny_test_data(exp)
        else:
            cfg["num_env_runners"] = TEST_ENV_RUNNERS
            cfg["num_cpus_per_env_runner"] = TEST_CPUS_PER_ENV_RUNNER
            cfg["num_envs_per_env_runner"] = 1
            family = family_of(exp.env)
            if family is not None and family.test_env_config:
                cfg["env_config"] = {**(cfg.get("env_config") or {}), **family.test_env_config}
        cfg["num_learners"] = 0
        for key in ("num_gpus_per_learner", "num_gpus_per_env_runner"):
            if cfg.get(key) and not cuda_available():
                exp.warnings.append(
                    f"{exp.source}: {exp.name}.config.{key}: "
                    f"{cfg[key]} -> 0 for --test (torch sees no CUDA device)"
                )
                cfg[key] = 0
        cfg["evaluation_interval"] = None
        cfg.pop("train_batch_size_per_learner", None)
        cfg["train_batch_size"] = TEST_BATCH
        if exp.run in ("MAPLE", "MOPO"):
            cfg[MAPLE_KEY] = {**(cfg.get(MAPLE_KEY) or {}), **TEST_MAPLE}
        if exp.run == "GARAT":
            cfg["garat_settings"] = {**(cfg.get("garat_settings") or {}), **TEST_GARAT}
        if exp.run == "BCO":
            cfg["bco_settings"] = {**(cfg.get("bco_settings") or {}), **TEST_BCO}
        if exp.run == "SOIL":
            cfg["soil_settings"] = {**(cfg.get("soil_settings") or {}), **TEST_SOIL}
        if exp.run.upper() in ("PPO", "APPO", "IMPALA", "GAIFO", "GARAT") or (
            exp.run == "SOIL" and not offline
        ):
            cfg["minibatch_size"] = TEST_MINIBATCH
            cfg["num_epochs"] = 1
        if "rollout_fragment_length" in cfg:
            cfg["rollout_fragment_length"] = "auto"
        exp.stop = dict(TEST_STOP)
    if num_env_runners is not None:
        if num_env_runners < 0:
            raise UsageError(
                f"{num_env_runners} is invalid: allowed an integer >= 0", key="--num-env-runners"
            )
        cfg["num_env_runners"] = num_env_runners
    if stop:
        exp.stop = {**exp.stop, **stop} if not test else dict(stop)
    if checkpoint_freq is not None:
        if checkpoint_freq < 0:
            raise UsageError(
                f"{checkpoint_freq} is invalid: allowed an integer >= 0", key="--checkpoint-freq"
            )
        exp.checkpoint_config["checkpoint_frequency"] = checkpoint_freq
    if keep_checkpoints is not None:
        if keep_checkpoints < 1:
            raise UsageError(
                f"{keep_checkpoints} is invalid: allowed an integer >= 1", key="--keep-checkpoints"
            )
        exp.checkpoint_config["num_to_keep"] = keep_checkpoints


def checkpoint_kwargs(exp: Experiment) -> dict[str, Any]:
    """Arguments of tune.CheckpointConfig: keep the last 3 and one at the end by default."""
    out = {"num_to_keep": DEFAULT_NUM_TO_KEEP, "checkpoint_at_end": True}
    out.update(exp.checkpoint_config)
    return out
