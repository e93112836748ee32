"""Cross-dynamics benchmark environments, registered as gymnasium ids on import.

Depends on nothing else of ours (DESIGN.md).
"""

from rllib_asor.envs.registration import register_envs

register_envs()
