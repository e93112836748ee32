"""GAIfO (Torabi, Warnell, Stone 2018, "Generative Adversarial Imitation from Observation") on
RLlib's new API stack: GAIL with a discriminator D(s, s′) that tells expert transitions from the
policy's, its reward −log(1 − D(s, s′)) fed to PPO.

The discriminator (ASOR's network and loss form: an MLP with one logit, class-balanced BCE,
expert labelled 1) is trained with its own Adam inside the Learner; a Learner connector piece
writes the reward before GAE, as ASOR's own piece does. Follows `Ricky-Zhu/GARAT
rl_gat/reinforcedgat.py` (`ATPEnv.step`: the GAIL reward −log(1 − σ(logit) + 1e-8), "used by
Faraz in the GAIfO implementation"); docs/baselines.md names each piece.

- `settings.py`: `GaifoSettings`, the YAML `gaifo:` block;
- `discriminator.py`: D(s, s′) and its loss (torch only);
- `reward.py`: features and reward (torch only);
- `trainer.py`: the discriminator, its optimizer and the expert rows;
- `connector.py`: the Learner connector piece;
- `learner.py`, `config.py`: `GaifoConfig` / `GAIfO`.
"""
