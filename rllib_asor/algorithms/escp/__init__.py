"""ESCP (Luo et al., AAAI 2022): a context-sensitive SAC, the base of the paper's Algorithm 1.

Faithful to the public code `FanmingL/ESCP` (file and function cited in each docstring):

- `encoder.py`: the context encoder ("environment probe"), fc128 → GRU64 → fc → z (tanh);
- `rmdm.py`: the RMDM loss (consistency + diversity) and its per-task moving averages;
- `windows.py`: the last-H-steps windows of (s_t, a_{t−1}), from flat replay columns and from
  live episodes;
- `replay.py`, `connector.py`, `module.py`, `learner.py`, `config.py`: ESCP on RLlib's new API
  stack (`EscpConfig`, a subclass of `SACConfig`) on the project's fast off-policy path.

`encoder.py`, `rmdm.py` and `windows.py` import torch/numpy only.
"""
