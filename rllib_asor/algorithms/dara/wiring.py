"""`with_dara(config, **settings)`: DARA's reward correction for an offline base (MAPLE, MOPO).

Like `with_asor`, it changes nothing else: a copy of the config whose `dara_settings` hold the
validated `DaraSettings`; the algorithm trains on relabelled copies of its dataset parts
(relabel.dara_parts) and reports the classifiers' statistics under `dara/...`. It combines with
`with_asor` in either order.
"""

from __future__ import annotations

from typing import Any

from rllib_asor.algorithms.dara.settings import DaraSettings

SUPPORTED = ("MAPLE", "MOPO")
"""Algorithms DARA is wired into (their configs carry `dara_settings`)."""


def with_dara(config: Any, **settings: Any) -> Any:
    """A copy of `config` (MAPLE or MOPO) with DARA; `settings` are `DaraSettings` fields.
    Raises ValueError (one line) for another algorithm or a bad setting."""
    dara = DaraSettings.from_dict(settings)
    names = {c.__name__ for c in getattr(config.algo_class, "__mro__", ())}
    if not hasattr(config, "dara_settings") or not names & set(SUPPORTED):
        algo = getattr(config.algo_class, "__name__", type(config).__name__)
        raise ValueError(
            f"DARA does not support algorithm {algo!r}: supported {', '.join(SUPPORTED)}"
        )
    config = config.copy(copy_frozen=False)
    config.dara_settings = dara.to_dict()
    return config
