"""Glue between the ASOR core and RLlib 2.60 (new API stack)."""

from rllib_asor.ray_compat import fast_connector_init

fast_connector_init()  # RLlib's connectors built without reading source files (same result)
