"""OSI (Yu, Tan, Liu, Turk; RSS 2017, "Preparing for the Unknown: Learning a Universal Policy
with Online System Identification"), UP-OSI on RLlib's new API stack.

A universal policy π(a | s, μ) and critics Q(s, a, μ) conditioned on the dynamics parameters μ
(the env's `info["dynamics_params"]`), trained with the true μ; an identification network
μ̂ = OSI(last H steps) trained by regression to the true μ; acting and evaluation use μ̂.
Follows `VincentYu68/policy_transfer policy_transfer/uposi/train_osi.py` (OSI: an MLP
256-128-64 ReLU over the flattened history of H = 10 steps, squared error to the true
parameters; data collected by the universal policy acting on OSI's estimates). Built on ESCP's
window machinery (`rllib_asor.algorithms.escp`: replay windows, the env-to-module window).

- `network.py`: the OSI network and its loss (torch only);
- `settings.py`: `OsiSettings`, the YAML `osi:` block;
- `module.py`, `replay.py`, `learner.py`, `config.py`: `OsiConfig` / `OSI`.
"""
