"""CaDM (Lee, Seo, Lee, Lee, Shin; ICML 2020, "Context-aware Dynamics Model for Generalization
in Model-Based Reinforcement Learning"), its model-free variant: a context encoder trained by
forward and backward prediction of the next state with a context-conditioned dynamics model,
the context fed to the policy and critics of SAC.

Follows `younggyoseo/CaDM` (`cadm/dynamics/mlp_cadm_ensemble_cem_dynamics.py`: the context
network 256-128-64 ReLU → 10 over the last 10 steps, the forward model 4×200 swish with a
Gaussian head on Δs, the backward model's squared error weighted by `back_coeff` 0.5;
`cadm/model_free/ppo_cadm.py`, `run_scripts/model_free/run_ppo_cadm.py`: the context, without
gradient, as an input of the model-free policy). Built on ESCP's window machinery
(`rllib_asor.algorithms.escp`). docs/baselines.md says why the model-free variant and where we
differ.

- `model.py`: the context network, the forward and backward models and CaDM's loss (torch);
- `settings.py`: `CadmSettings`, the YAML `cadm:` block;
- `module.py`, `learner.py`, `config.py`: `CadmConfig` / `CaDM`.
"""
