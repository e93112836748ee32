"""rllib-asor: ASOR (ICML 2025) as an add-on for Ray RLlib's new API stack.

`rllib_asor.with_asor(algo_config, **settings)` switches ASOR on for an RLlib config;
`rllib_asor.asor` holds the method itself (torch + numpy, no ray).
"""

from __future__ import annotations

from typing import Any

from rllib_asor.asor.config import AsorConfig

__all__ = ["AsorConfig", "with_asor"]
__version__ = "0.1.0"


def with_asor(algo_config: Any, **asor_settings: Any) -> Any:
    """Return `algo_config` with ASOR wired in (see `rllib_asor.rllib.wiring.with_asor`)."""
    from rllib_asor.rllib.wiring import with_asor as _with_asor

    return _with_asor(algo_config, **asor_settings)
