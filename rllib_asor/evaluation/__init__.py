"""Evaluating trained policies: `rollout` (deterministic episodes on a gymnasium env; the offline
scorer and the MuJoCo benchmarks). The race's own evaluation (every map, unseen courses, GIFs)
is `rllib_asor.race.evaluation`. `rllib evaluate` samples through the algorithm's own env runner
instead (rllib_asor/cli/evaluate.py), so any env and its connectors work unchanged."""
