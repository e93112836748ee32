"""The `rllib` command: train | evaluate | report."""
