"""Evaluating trained policies: `race` (every map, unseen courses, GIFs; rllib quickstart and
the race benchmark) and `rollout` (deterministic episodes on a gymnasium env; the offline scorer
and the MuJoCo benchmarks). `rllib evaluate` samples through the algorithm's own env runner
instead (rllib_asor/cli/evaluate.py), so any env and its connectors work unchanged."""
