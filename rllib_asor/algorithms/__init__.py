"""The algorithms we ship, one folder each as in RLlib's own `ray/rllib/algorithms/<name>/`.

- `common/`: what every Learner shares (same-math speed-ups, pipeline placement, callbacks,
  fault tolerance);
- `ppo/`: lean PPO (row dropping) and overlapped sampling;
- `sac/`: the fast off-policy path (concat-MLP critics, flat replay, multi-step Learner calls);
- `cql/`: offline inputs for CQL;
- `escp/`, `maple/`, `mopo/`: the paper's other bases.
- `osi/`, `cadm/`, `dara/`: the paper's other baselines; `bco/`, `soil/`, `gaifo/`, `garat/`: its
  imitation-from-observation baselines.

Nothing here imports ASOR: the glue in `rllib_asor.rllib` mixes ASOR into these Learners.
"""
