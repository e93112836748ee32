"""Names of RLModules a YAML can give (`module_class: race_net`); `registry` maps them to classes."""

from rllib_asor.models.registry import MODULES, get_module_class

__all__ = ["MODULES", "get_module_class"]
