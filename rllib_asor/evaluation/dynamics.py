"""Episode returns per ``info["dynamics_id"]``, on RLlib's own (evaluation) env runners.

`DynamicsReturnsCallback` logs each finished episode's return under
``dynamics/<id>/episode_return_mean`` (and ``.../num_episodes``) of the env runner's metrics:
training episodes land in ``env_runners/dynamics/...``, the greedy episodes of the evaluation
env runners in ``evaluation/env_runners/dynamics/...`` of the Tune results, which
`rllib compare` reads (rllib_asor/report/scores.py). An env that reports no ``dynamics_id``
logs nothing extra.

Switch it on from a YAML file next to RLlib's evaluation settings::

    config:
      evaluation_interval: 5
      evaluation_duration: 10
      callbacks: rllib_asor.evaluation.dynamics.DynamicsReturnsCallback
"""

from __future__ import annotations

from typing import Any

from ray.rllib.callbacks.callbacks import RLlibCallback

DYNAMICS_KEY = "dynamics_id"
METRIC_GROUP = "dynamics"
RETURN_LEAF = "episode_return_mean"
COUNT_LEAF = "num_episodes"


def dynamics_id(episode: Any) -> Any:
    """The episode's ``dynamics_id`` from its last info (else its first); None if absent.

    Multi-agent episodes: the first agent info that has one."""
    for index in (-1, 0):
        try:
            info = episode.get_infos(index)
        except (AttributeError, IndexError, KeyError, TypeError):
            continue
        if isinstance(info, dict) and DYNAMICS_KEY in info:
            return info[DYNAMICS_KEY]
        if isinstance(info, dict):
            for sub in info.values():
                if isinstance(sub, dict) and DYNAMICS_KEY in sub:
                    return sub[DYNAMICS_KEY]
    return None


def _plain(value: Any) -> str:
    """A dynamics id as a metric key part (numpy scalars and floats like 2.0 -> "2")."""
    if hasattr(value, "item"):
        value = value.item()
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    return str(value)


class DynamicsReturnsCallback(RLlibCallback):
    """Log every episode's return under its ``dynamics_id`` (module doc)."""

    def on_episode_end(self, *, episode: Any, metrics_logger: Any = None, **kwargs: Any) -> None:
        did = dynamics_id(episode)
        if did is None or metrics_logger is None:
            return
        key = _plain(did)
        metrics_logger.log_value(
            (METRIC_GROUP, key, RETURN_LEAF), float(episode.get_return()), reduce="mean"
        )
        metrics_logger.log_value((METRIC_GROUP, key, COUNT_LEAF), 1, reduce="sum")
