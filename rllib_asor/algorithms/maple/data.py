"""The offline dataset's episodes as numpy trajectories (no Ray Data: MAPLE needs them in order).

Reads the parts written by `rllib data collect` (`rllib_asor/data/format.py`: parquet rows,
column `item` = a msgpack'd `SingleAgentEpisode` state) straight with pyarrow.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from rllib_asor.algorithms.maple.segments import Trajectories


def read_part(path: str | Path) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, bool]]:
    """(obs [T+1], actions [T], rewards [T], terminated) of every episode in one part dir."""
    import msgpack
    import msgpack_numpy as mnp
    import pyarrow.parquet as pq
    from ray.rllib.env.single_agent_episode import SingleAgentEpisode

    files = sorted(Path(path).glob("*.parquet"))
    if not files:
        raise ValueError(f"no parquet files in {path}; make the data first: `make datasets`")
    out = []
    for file in files:
        for raw in pq.read_table(file).column("item").to_pylist():
            ep = SingleAgentEpisode.from_state(msgpack.unpackb(raw, object_hook=mnp.decode))
            obs = np.asarray(ep.get_observations(), dtype=np.float32)
            acts = np.asarray(ep.get_actions(), dtype=np.float32)
            rews = np.asarray(ep.get_rewards(), dtype=np.float32)
            if len(acts) == 0:
                continue
            out.append((obs, acts.reshape(len(acts), -1), rews, bool(ep.is_terminated)))
    return out


def load_trajectories(paths: Sequence[str]) -> Trajectories:
    """All episodes of the parts `paths` (`.../<task>/<dynamics>/<quality>`), in order; the
    part index is each row's `dynamics_ids` entry."""
    episodes, ids = [], []
    for i, path in enumerate(paths):
        part = read_part(path)
        episodes += part
        ids += [i] * len(part)
    return Trajectories.from_episodes(episodes, ids)
