"""RLlib glue for offline datasets: point an offline config (CQL, BC, ...) at a dataset.

The datasets themselves (layout, collecting, scoring) are `rllib_asor.data`.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

from rllib_asor.data.format import load_dataset


def offline_input(
    config: Any,
    path: str | os.PathLike[str],
    *,
    dynamics: str | Sequence[str] | None = None,
    quality: str | Sequence[str] | None = None,
    **offline_data: Any,
) -> Any:
    """Point an offline RLlib config (CQL, BC, ...) at a dataset; returns the same config.

    Sets `config.environment(<the dataset's env>)` when no env is set (the spaces come from
    it) and `config.offline_data(input_=<parquet dirs>, input_read_episodes=True, ...)`;
    extra keyword arguments go to `offline_data` (e.g. `dataset_num_iters_per_learner`).
    """
    import rllib_asor.envs  # noqa: F401  (registers the env ids in this process)

    ds = load_dataset(path, dynamics=dynamics, quality=quality)
    if config.env is None:
        config.environment(ds.env)
    kwargs: dict[str, Any] = {"input_": list(ds.paths), "input_read_episodes": True}
    kwargs.update(offline_data)
    config.offline_data(**kwargs)
    return config
