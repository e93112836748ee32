"""RLModules for our observation spaces (the race network); `registry` maps names to them."""

from rllib_asor.models.registry import MODULES, get_module_class

__all__ = ["MODULES", "get_module_class"]
