"""Offline datasets for cross-dynamics RL (D4RL-like), outside the RLlib glue.

- `format`: the dataset layout and manifest, loading (`load_dataset`) and writing episodes;
- `collect`: training the policies per dynamics and sampling the datasets (`rllib data collect`);
- `scoring`: D4RL-style normalised scores of a policy (`rllib data score`).

`rllib_asor.algorithms.cql.offline.offline_input` points an offline RLlib config at a dataset.
"""
