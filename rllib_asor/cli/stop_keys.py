"""Stop keys checked before Ray starts: each `stop:` key must name a metric the chosen
algorithm reports, else Tune warns once and trains without limit.

The catalogue is RLlib 2.60's new-stack result layout (one real PPO and SAC iteration,
flattened with `/` as Tune flattens it for `stop`): Tune's own counters, the top-level step
counter, `env_runners/...` (and `evaluation/env_runners/...` when evaluation is on),
`learners/<module>/<stat>` with the stats the algorithm's Learner code names, `replay_buffer/...`
for off-policy algorithms, `timers/...`, `perf/...`, `fault_tolerance/...`, and our own `asor/...`
(with an `asor:` block) and `race/...` (the race envs).
"""

from __future__ import annotations

import ast
import difflib
import functools
import importlib
import re
import sys
from pathlib import Path
from typing import Any

from rllib_asor.cli.errors import Problems, UsageError

TUNE_KEYS = (
    "training_iteration",
    "time_total_s",
    "time_this_iter_s",
    "time_since_restore",
    "iterations_since_restore",
    "timestamp",
)
"""What Tune adds to every result (numbers)."""

TOP_KEYS = ("num_env_steps_sampled_lifetime", "num_training_step_calls_per_iteration")
"""RLlib's top-level counters on the new API stack."""

ENV_RUNNER_KEYS = (
    "episode_return_mean",
    "episode_return_max",
    "episode_return_min",
    "episode_len_mean",
    "episode_len_max",
    "episode_len_min",
    "episode_duration_sec_mean",
    "num_episodes",
    "num_episodes_lifetime",
    "num_env_steps_sampled",
    "num_env_steps_sampled_lifetime",
    "env_reset_timer",
    "env_step_timer",
    "rlmodule_inference_timer",
    "sample",
    "time_between_sampling",
    "weights_seq_no",
    "env_to_module_sum_episodes_length_in",
    "env_to_module_sum_episodes_length_out",
)
"""`env_runners/<key>` (scalars)."""

ENV_RUNNER_PER_ID = (
    "agent_episode_return_mean",
    "module_episode_return_mean",
    "num_agent_steps_sampled",
    "num_agent_steps_sampled_lifetime",
    "num_module_steps_sampled",
    "num_module_steps_sampled_lifetime",
)
"""`env_runners/<key>/<agent or module id>`."""

DEFAULT_IDS = ("default_agent", "default_policy")
"""The agent and module id of a single-agent run."""

ENV_RUNNER_OPEN = (
    "env_to_module_connector",
    "module_to_env_connector",
    "num_env_steps_sampled_lifetime_throughput",
    "dynamics",  # rllib_asor.evaluation.dynamics (`rllib ab`): dynamics/<id>/<stat>
)
"""`env_runners/<key>/...` whose deeper names are not checked (timers, per-dynamics returns)."""

GROUP_KEYS = {
    "timers": (
        "env_runner_sampling_timer",
        "learner_update_timer",
        "training_iteration",
        "training_step",
        "restore_env_runners",
        "synch_env_connectors",
        "synch_weights",
        "evaluation_iteration",
        "restore_eval_env_runners",
        "synch_eval_env_connectors",
        "replay_buffer_add_data_timer",
        "replay_buffer_sampling_timer",
        "replay_buffer_update_prios_timer",
    ),
    "perf": ("cpu_util_percent", "ram_util_percent", "gpu_util_percent0", "vram_util_percent0"),
    "fault_tolerance": (
        "num_env_runners_dropped_lifetime",
        "num_healthy_workers",
        "num_remote_worker_restarts",
    ),
    "env_runner_group": ("actor_manager_num_outstanding_async_reqs",),
}
"""`<group>/<key>`."""

EVALUATION_KEYS = (
    "actor_manager_num_outstanding_async_reqs",
    "num_env_runners_dropped_lifetime",
    "num_healthy_workers",
    "num_remote_worker_restarts",
)
"""`evaluation/<key>` next to `evaluation/env_runners/...`."""

REPLAY_BUFFER_PER_ID = re.compile(r"^(agent|module)_")
"""`replay_buffer/<agent_...|module_...|num_agent_...|num_module_...>/<id>`."""

LEARNER_PATTERNS = (
    re.compile(r"^[a-z0-9_]+_learning_rate$"),  # `<optimizer>_learning_rate`
    re.compile(r"^gradients_[a-z0-9_]+_global_norm$"),
    re.compile(r"^[a-z0-9_]+_throughput$"),
)
"""Learner stats whose names RLlib builds from the optimizer's name."""

LEARNER_SUGGESTIONS = (
    "total_loss",
    "policy_loss",
    "vf_loss",
    "vf_explained_var",
    "entropy",
    "mean_kl_loss",
    "qf_loss",
    "alpha_loss",
    "alpha_value",
    "num_module_steps_trained",
    "num_module_steps_trained_lifetime",
    "num_env_steps_trained_lifetime",
)


@functools.lru_cache(maxsize=64)
def _literals(folder: str) -> frozenset[str]:
    """Every string literal that looks like a metric name in the .py files under `folder`."""
    words: set[str] = set()
    for path in Path(folder).rglob("*.py"):
        if "tests" not in path.parts and "examples" not in path.parts:
            words |= _file_literals(str(path))
    return frozenset(words)


@functools.lru_cache(maxsize=512)
def _file_literals(path: str) -> frozenset[str]:
    """The metric-name-like string literals of one .py file."""
    try:
        tree = ast.parse(Path(path).read_text(encoding="utf-8", errors="ignore"))
    except (SyntaxError, ValueError, OSError):
        return frozenset()
    return frozenset(
        node.value
        for node in ast.walk(tree)
        if isinstance(node, ast.Constant)
        and isinstance(node.value, str)
        and re.fullmatch(r"[a-z][a-z0-9_]{1,60}", node.value)
    )


def _package_folder(module: str) -> str | None:
    """The folder of `module`'s package (its own folder for a package's module)."""
    mod = sys.modules.get(module) or importlib.import_module(module)
    file = getattr(mod, "__file__", None)
    return str(Path(file).parent) if file else None


def learner_stats(cfg: Any, asor: bool) -> frozenset[str]:
    """The stat names the Learner code of `cfg`'s algorithm names (string literals of the
    packages of its Algorithm and Learner classes and their bases, RLlib's Learner core)."""
    import ray.rllib.core.learner as core
    import ray.rllib.utils.metrics as metrics

    classes: list[type] = list(type(cfg).__mro__)
    algo = getattr(cfg, "algo_class", None)
    if isinstance(algo, type):
        classes += list(algo.__mro__)
    try:
        learner = cfg.learner_class
    except Exception:  # an algorithm without a Learner (nothing to add)
        learner = None
    if isinstance(learner, type):
        classes += list(learner.__mro__)
    folders = {str(Path(core.__file__).parent)}
    files: set[str] = {metrics.__file__}
    for cls in classes:
        module = cls.__module__
        depth = len(module.split("."))
        ours = module.startswith("rllib_asor.algorithms.") and depth >= 4
        if ours or module.startswith("ray.rllib.algorithms.") and depth >= 5:
            folder = _package_folder(module)  # the algorithm's own package
            if folder is not None:
                folders.add(folder)
        elif module.startswith(("ray.rllib.", "rllib_asor.")):
            files.add(sys.modules[module].__file__ or "")
    if asor:
        import rllib_asor.asor as asor_pkg
        import rllib_asor.rllib as rllib_pkg

        folders |= {str(Path(asor_pkg.__file__).parent), str(Path(rllib_pkg.__file__).parent)}
    out: set[str] = set().union(*(_file_literals(f) for f in sorted(files) if f))
    for folder in sorted(folders):
        out |= _literals(folder)
    return frozenset(out)


def asor_metrics() -> frozenset[str]:
    """The `asor/<name>` metrics (`rllib_asor.rllib.callbacks`)."""
    from rllib_asor.rllib.callbacks import ASOR_METRICS

    return frozenset(ASOR_METRICS) | {"disc_acc"}


def race_metrics() -> frozenset[str]:
    """The `race/<name>` metrics of the race envs' callbacks and curricula."""
    try:
        from rllib_asor.race.config import PER_MAP_METRICS, RACE_METRICS
    except ImportError:
        return frozenset()
    extra = {"policy_entropy", "curriculum_stage", "curriculum_score", "episodes"}
    extra |= {"success_sum", "goal_reward_sum"}
    return frozenset(RACE_METRICS) | set(PER_MAP_METRICS) | extra


class Catalogue:
    """What one experiment's trials report, as a test of stop keys."""

    def __init__(self, exp: Any, cfg: Any) -> None:
        from rllib_asor.registry.families import family_of

        self.run = exp.run
        self.asor = exp.asor is not None
        family = family_of(exp.env)
        self.race = family is not None and family.metrics_callbacks is not None
        self.evaluation = bool(getattr(cfg, "evaluation_interval", None))
        self.replay = getattr(cfg, "replay_buffer_config", None) is not None
        self.multi = bool(getattr(cfg, "is_multi_agent", False))
        source = getattr(cfg, "input_", "sampler")
        self.offline = bool(source) and source != "sampler"
        own = {"callbacks", "callbacks_class"} & set(exp.config)
        self.own_callbacks = bool(own)
        self.stats = learner_stats(cfg, self.asor)

    def _env_runners(self, rest: list[str]) -> bool:
        if len(rest) == 1:
            return rest[0] in ENV_RUNNER_KEYS
        if rest[0] in ENV_RUNNER_PER_ID:  # several agents: their own ids, not the default's
            return len(rest) == 2 and not (self.multi and rest[1] in DEFAULT_IDS)
        if rest[0] == "race":
            return self.race and rest[-1] in race_metrics()
        return rest[0] in ENV_RUNNER_OPEN

    def knows(self, key: str) -> bool:
        """True if the algorithm (with this experiment's settings) reports `key`."""
        parts = key.split("/")
        head, rest = parts[0], parts[1:]
        if not rest:
            return key in TUNE_KEYS or key in TOP_KEYS
        if head == "env_runners":  # an offline run steps no env: no episodes to report
            return not self.offline and self._env_runners(rest)
        if head == "evaluation":
            if not self.evaluation:
                return False
            if rest[0] == "env_runners" and len(rest) > 1:
                return self._env_runners(rest[1:])
            return len(rest) == 1 and rest[0] in EVALUATION_KEYS
        if head == "learners":
            if len(rest) < 2:
                return False
            stat = rest[1]
            return stat in self.stats or any(p.match(stat) for p in LEARNER_PATTERNS)
        if head == "replay_buffer":
            return (
                self.replay
                and not self.offline
                and (
                    len(rest) == 1
                    or REPLAY_BUFFER_PER_ID.match(rest[0].replace("num_", "", 1)) is not None
                )
            )
        if head == "asor":
            return self.asor and len(rest) <= 2 and rest[-1] in asor_metrics()
        if head == "race":
            return self.race and len(rest) <= 2 and rest[-1] in race_metrics()
        return head in GROUP_KEYS and len(rest) == 1 and rest[0] in GROUP_KEYS[head]

    def examples(self) -> list[str]:
        """Concrete keys for did-you-mean (the common ones of each group)."""
        runners = [f"env_runners/{k}" for k in ENV_RUNNER_KEYS]
        out = [*TUNE_KEYS, *TOP_KEYS, *runners]
        if self.evaluation:
            out += [f"evaluation/{k}" for k in runners]
        out += [f"learners/default_policy/{k}" for k in LEARNER_SUGGESTIONS if k in self.stats]
        out += [f"learners/__all_modules__/{k}" for k in ("num_env_steps_trained_lifetime",)]
        if self.asor:
            out += [f"asor/{k}" for k in sorted(asor_metrics())]
        if self.race:
            out += [f"race/{k}" for k in sorted(race_metrics())]
        for group, keys in GROUP_KEYS.items():
            out += [f"{group}/{k}" for k in keys]
        return out

    def why_not(self, key: str) -> str:
        """The reason `key` is refused, with a did-you-mean."""
        head = key.split("/")[0]
        if head == "evaluation" and not self.evaluation:
            return (
                f"evaluation/... is reported only when evaluation runs; allowed: set "
                f"config.evaluation_interval, or stop on {key.replace('evaluation/', '', 1)}"
            )
        if head in ("env_runners", "replay_buffer") and self.offline:
            return (
                f"an offline run ({self.run} reading input files) steps no env, so it reports "
                f"no {head}/...; allowed: training_iteration, time_total_s, learners/..., or "
                "evaluation/env_runners/... with config.evaluation_interval"
            )
        if head == "asor" and not self.asor:
            return "asor/... metrics exist only with an asor: block in config"
        if head == "race" and not self.race:
            return "race/... metrics exist only on the race envs (game_env/...)"
        if head == "replay_buffer" and not self.replay:
            return f"{self.run} has no replay buffer"
        return f"not a metric {self.run} reports; {did_you_mean(key, self.examples())}"


def did_you_mean(key: str, candidates: list[str]) -> str:
    """'did you mean X? ' (same last name first, then difflib) + what is allowed."""
    last = key.rsplit("/", 1)[-1]
    same = [c for c in candidates if c.rsplit("/", 1)[-1] == last and c != key]
    close = same[:2] or difflib.get_close_matches(key, candidates, n=2, cutoff=0.6)
    hint = f"did you mean {' or '.join(close)}? " if close else ""
    return (
        f"{hint}allowed: a result key such as training_iteration, time_total_s, "
        "num_env_steps_sampled_lifetime, env_runners/episode_return_mean "
        "(nested keys joined with /)"
    )


def require_stop(exp: Any) -> None:
    """A run needs a stop: without one Tune trains until interrupted. UsageError naming what
    is allowed when neither the file nor `--test`/`--stop` gave one."""
    if not exp.stop:
        raise UsageError(
            "missing: without one the run would train forever; allowed: a result name and the "
            "value that ends the run, e.g. stop: {num_env_steps_sampled_lifetime: 100000} "
            "(or training_iteration, time_total_s, env_runners/episode_return_mean), or "
            "--stop KEY=VALUE",
            source=exp.source,
            key=f"{exp.name}.stop",
        )


def check_stop(exp: Any, cfg: Any, evaluation: bool = False) -> None:
    """UsageError (one line each, did-you-mean) for every stop key `cfg`'s algorithm does not
    report; a file with callbacks of its own may name the metrics they log (a warning unless
    the key is a near miss of a known one). `evaluation`: evaluation runs whatever the config
    says (`rllib ab` turns it on)."""
    if not exp.stop:
        return
    catalogue = Catalogue(exp, cfg)
    catalogue.evaluation = catalogue.evaluation or evaluation
    problems = Problems()
    for key in exp.stop:
        if not isinstance(key, str) or catalogue.knows(key):
            continue
        close = difflib.get_close_matches(key, catalogue.examples(), n=1, cutoff=0.85)
        if catalogue.own_callbacks and not close:
            exp.warnings.append(
                f"{exp.source}: stop key '{key}' is not a metric {exp.run} reports; it stops "
                "the run only if your callbacks log it"
            )
            continue
        problems.add(
            UsageError(catalogue.why_not(key), source=exp.source, key=f"{exp.name}.stop.{key}")
        )
    problems.raise_any()
