"""GARAT (Desai, Durugkar, Karnan, Warnell, Hanna, Stone; NeurIPS 2020, "An Imitation from
Observation Approach to Transfer Learning with Dynamics Mismatch") on RLlib's new API stack.

Grounding: an action transformer g(s, a) = a + Δ(s, a) is trained GAIL-style, as GAIfO's policy
in the grounding MDP (`GroundingEnv`: observation (s_t, a_t), action Δ, the source env stepped
with clip(a_t + Δ)), its discriminator D(s, s′) (or (s, a, s′), (s, a, s′ − s):
`disc_input`) telling the target's transitions (`demonstrations:`) from the grounded source's. Then the agent's policy is trained by PPO in the
grounded source (`GroundedEnv`: the source env whose actions pass through g's deterministic Δ)
and evaluated in the target. Follows `Ricky-Zhu/GARAT rl_gat/reinforcedgat.py` (`ATPEnv`,
`GroundedEnv`, `Discriminator`); docs/baselines.md names each piece and what differs.

- `settings.py`: `GaratSettings`, the YAML `garat:` block;
- `envs.py`: `GroundingEnv`, `GroundedEnv`, the transformer's deterministic Δ;
- `grounding.py`: the grounding step (a GAIfO run on `GroundingEnv`);
- `config.py`: `GaratConfig` / `GARAT`.
"""
