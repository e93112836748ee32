"""SOIL (Radosavovic, Wang, Malik, Efros, IROS 2021, "State-Only Imitation Learning for Dexterous
Manipulation") on RLlib's new API stack: policy gradient on the env's reward plus an auxiliary
imitation term on expert states, whose actions an inverse dynamics model p(a | s, s′) trained on
the policy's own transitions infers.

Online it is PPO with SOIL's Learner: a Learner connector piece adds each batch's (s, a, s′) to
the model's buffer, trains it and labels the expert transitions; the PPO loss gains
w_k · (N_demo / N_batch) · mean(−log π(â | s_expert)), w_k = demo_weight · demo_decay^k (SOIL's
DAPG-style demonstration term, k the training iteration). Offline (`input:` set) the same term
is added to MARWIL's loss and the model is fitted once on the dataset's own transitions.

- `settings.py`: `SoilSettings`, the YAML `soil:` block;
- `connector.py`: the inverse dynamics model's piece (online);
- `learner.py`: the Learner mixin (the term, the model's state in checkpoints);
- `config.py`: `SoilConfig` / `SOIL`.
"""
