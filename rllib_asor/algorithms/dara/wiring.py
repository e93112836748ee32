"""`with_dara(config, **settings)`: DARA's reward correction for an offline base (MAPLE, MOPO, CQL).

Like `with_asor`, it changes nothing else: a copy of the config whose `dara_settings` hold the
validated `DaraSettings`; the algorithm trains on relabelled copies of its dataset parts
(relabel.dara_parts) and reports the classifiers' statistics under `dara/...`. It combines with
`with_asor` in either order.
"""

from __future__ import annotations

from typing import Any

from rllib_asor.algorithms.dara.settings import DaraSettings

SUPPORTED = ("MAPLE", "MOPO", "CQL")
"""Algorithms DARA is wired into: MAPLE and MOPO relabel when they are built (their configs
carry `dara_settings`); CQL here, at once (its data goes through RLlib's Ray Data reader)."""


def with_dara(config: Any, **settings: Any) -> Any:
    """A copy of `config` (MAPLE, MOPO or CQL) with DARA; `settings` are `DaraSettings` fields.
    MAPLE/MOPO relabel their data when built; for CQL the relabelled copies are made now and
    `config.input_` points at them (`input_read_episodes` as before). Raises ValueError (one
    line) for another algorithm, a CQL config without dataset parts, or a bad setting."""
    dara = DaraSettings.from_dict(settings)
    names = {c.__name__ for c in getattr(config.algo_class, "__mro__", ())}
    if not names & set(SUPPORTED):
        algo = getattr(config.algo_class, "__name__", type(config).__name__)
        raise ValueError(
            f"DARA does not support algorithm {algo!r}: supported {', '.join(SUPPORTED)}"
        )
    config = config.copy(copy_frozen=False)
    if hasattr(config, "dara_settings"):
        config.dara_settings = dara.to_dict()
        return config
    paths = config.input_ if isinstance(config.input_, list) else [config.input_]
    if not paths or not all(isinstance(p, str) and p != "sampler" for p in paths):
        raise ValueError(
            "DARA on CQL needs the dataset parts first: offline_input(config, path) or "
            "config.offline_data(input_=[part dirs such as 'data/offline/hopper/original/medium'])"
        )
    from rllib_asor.algorithms.dara.relabel import dara_parts

    relabelled, _ = dara_parts(paths, dara, seed=int(config.seed or 0))
    config.offline_data(input_=relabelled)
    return config
