"""Env ids for RLlib and Tune (`envs`) and what the CLI knows about each env family (`families`)."""
