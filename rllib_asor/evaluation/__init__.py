"""Evaluating trained policies, in one place.

- `rollout`: the one episode loop (`play`: envs stepped together to the end of an episode;
  `rollout`: episodes one at a time on one env) and the policies it runs (`module_actor`,
  `module_policy`, `deterministic_action`; the module of an Algorithm or checkpoint,
  `policy_module`). ESCP's window and MAPLE's GRU context are actors of their own
  (`algorithms/escp/evaluate.py`, `algorithms/maple/evaluation.py`); the race's courses, table
  and GIF are `rllib_asor.race.evaluation`; D4RL scores are `rllib_asor.data.scoring`.
- `summary`: statistics of finished episodes (what `rllib evaluate` prints; it samples through
  the algorithm's own env runner, so any env and its connectors work unchanged).
- `dynamics`: episode returns per ``info["dynamics_id"]`` on RLlib's own env runners.
"""
