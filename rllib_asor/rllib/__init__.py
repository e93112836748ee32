"""Glue between the ASOR core and RLlib 2.60 (new API stack)."""
