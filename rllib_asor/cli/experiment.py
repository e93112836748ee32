"""One experiment of a YAML file, from text to Tune: parse → translate → validate → build.

- `spec`: parse the file into `Experiment`s (`legacy` translates old keys on the way);
- `overrides`: command-line options (`--test`, `--stop`, ...) on top of the file;
- `offline_inputs`: missing datasets refused before Ray starts, stand-ins for `--test`;
- `validate`: everything checkable before Ray starts (keys, values, env, `asor:`);
- `build`: the AlgorithmConfig of a grid point, the Tune param space, the CPUs a trial needs.

This module names the steps so that callers import one place.
"""

from __future__ import annotations

from rllib_asor.cli.build import (
    algorithm_class,
    build_algo_config,
    offline_data_cpus,
    param_space,
    required_cpus,
)
from rllib_asor.cli.offline_inputs import check_offline_input, missing_inputs
from rllib_asor.cli.overrides import (
    TEST_BATCH,
    apply_overrides,
    checkpoint_kwargs,
    parse_stop_flags,
)
from rllib_asor.cli.spec import (
    DEFAULT_NUM_TO_KEEP,
    Experiment,
    from_flags,
    load_file,
    parse_experiment,
)
from rllib_asor.cli.validate import check_file, validate, validate_asor, validate_env

__all__ = [
    "DEFAULT_NUM_TO_KEEP",
    "TEST_BATCH",
    "Experiment",
    "algorithm_class",
    "apply_overrides",
    "build_algo_config",
    "check_file",
    "check_offline_input",
    "checkpoint_kwargs",
    "from_flags",
    "load_file",
    "missing_inputs",
    "offline_data_cpus",
    "param_space",
    "parse_experiment",
    "parse_stop_flags",
    "required_cpus",
    "validate",
    "validate_asor",
    "validate_env",
]
