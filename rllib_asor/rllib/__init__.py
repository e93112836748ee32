"""Glue between the ASOR core and RLlib 2.60 (new API stack)."""

from rllib_asor.ray_compat import fast_rllib

fast_rllib()  # RLlib's connector builds and per-step unbatching made cheap (same results)
