"""rllib-asor: ASOR (ICML 2025) as an add-on for Ray RLlib's new API stack.

`rllib_asor.with_asor(algo_config, **settings)` switches ASOR on for an RLlib config;
`rllib_asor.AsorConfig` holds the settings; `rllib_asor.FastSACConfig` is SAC on our fast
off-policy path (a choice for both arms: `with_asor` never changes the base algorithm);
`rllib_asor.asor` is the method itself (torch + numpy, no ray). Importing the package registers
our gymnasium ids (`rllib_asor/LavaWorld-v0`, ...; entry points only, nothing heavy);
everything else is imported lazily.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from rllib_asor.registry.envs import register_envs

register_envs()

if TYPE_CHECKING:
    from rllib_asor.algorithms.bco.config import BcoConfig
    from rllib_asor.algorithms.escp.config import EscpConfig
    from rllib_asor.algorithms.gaifo.config import GaifoConfig
    from rllib_asor.algorithms.garat.config import GaratConfig
    from rllib_asor.algorithms.maple.maple import MapleConfig, MopoConfig
    from rllib_asor.algorithms.osi.config import OsiConfig
    from rllib_asor.algorithms.sac.config import FastSACConfig
    from rllib_asor.algorithms.soil.config import SoilConfig, SoilOfflineConfig
    from rllib_asor.asor.config import AsorConfig

__all__ = [
    "AsorConfig",
    "BcoConfig",
    "EscpConfig",
    "FastSACConfig",
    "GaifoConfig",
    "GaratConfig",
    "MapleConfig",
    "MopoConfig",
    "OsiConfig",
    "SoilConfig",
    "SoilOfflineConfig",
    "with_asor",
    "with_dara",
]
__version__ = "0.1.0"


def with_asor(algo_config: Any, **asor_settings: Any) -> Any:
    from rllib_asor.rllib.wiring import with_asor as _with_asor

    return _with_asor(algo_config, **asor_settings)


def _with_asor_doc() -> str:
    from rllib_asor.asor.config import settings_help  # pydantic, no torch: cheap to import

    head = """Return a copy of `algo_config` (PPO, SAC, CQL, ESCP, MAPLE or MOPO; new API
    stack, torch) with ASOR.

    `asor_settings` are `AsorConfig` fields (below); none gives the robust default,
    `preset="paper"` the published form, e.g. `with_asor(config, lambda_=0.1, seed=0)`.
    Bad settings raise ValueError naming the key, the value and what is allowed.
    """
    return head + "\n    " + settings_help().replace("\n", "\n    ")


with_asor.__doc__ = _with_asor_doc()


def with_dara(algo_config: Any, **dara_settings: Any) -> Any:
    """Return a copy of `algo_config` (MAPLE, MOPO or CQL) with DARA's reward correction of the
    source rows (`rllib_asor.algorithms.dara`; settings: `DaraSettings`). Bad settings raise
    ValueError naming the key, the value and what is allowed."""
    from rllib_asor.algorithms.dara.wiring import with_dara as _with_dara

    return _with_dara(algo_config, **dara_settings)


def __getattr__(name: str) -> Any:
    if name == "AsorConfig":
        from rllib_asor.asor.config import AsorConfig

        return AsorConfig
    if name in ("MapleConfig", "MopoConfig"):  # MAPLE / MOPO, imported on first use
        from rllib_asor.algorithms.maple import maple

        return getattr(maple, name)
    if name == "EscpConfig":  # ESCP, imported on first use
        from rllib_asor.algorithms.escp.config import EscpConfig

        return EscpConfig
    if name == "FastSACConfig":  # SAC on the fast off-policy path, imported on first use
        from rllib_asor.algorithms.sac.config import FastSACConfig

        return FastSACConfig
    if name == "OsiConfig":  # UP-OSI, imported on first use
        from rllib_asor.algorithms.osi.config import OsiConfig

        return OsiConfig
    if name == "GaifoConfig":  # GAIfO, imported on first use
        from rllib_asor.algorithms.gaifo.config import GaifoConfig

        return GaifoConfig
    if name == "GaratConfig":  # GARAT, imported on first use
        from rllib_asor.algorithms.garat.config import GaratConfig

        return GaratConfig
    if name == "BcoConfig":  # BCO, imported on first use
        from rllib_asor.algorithms.bco.config import BcoConfig

        return BcoConfig
    if name in ("SoilConfig", "SoilOfflineConfig"):  # SOIL (online / offline), on first use
        from rllib_asor.algorithms.soil import config as soil

        return getattr(soil, name)
    raise AttributeError(f"module 'rllib_asor' has no attribute {name!r}")
