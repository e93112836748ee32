"""DARA (Liu, Zhang, Wang, ICLR 2022): dynamics-aware reward augmentation of offline data.

Two domain classifiers, p(target | s, a, s′) and p(target | s, a), tell the source rows (data
from other dynamics) from the target rows; each source row's reward gets η·Δr with
Δr = log p(t|s,a,s′)/p(s|s,a,s′) − log p(t|s,a)/p(s|s,a), the log ratio of the target's to the
source's transition probability (DARA's r − η·ΔR). The classifiers are DARC's
(`google-research/google-research darc/classifiers.py`, `darc_agent.py`).

- `classifiers.py`: the classifier pair, its loss and Δr (torch only);
- `settings.py`: `DaraSettings`, the YAML `dara:` block;
- `relabel.py`: train the classifiers on the dataset parts and write relabelled copies (numpy,
  pyarrow, torch; no ray);
- `wiring.py`: `with_dara(config, **settings)` for MAPLE, MOPO and CQL.
"""
