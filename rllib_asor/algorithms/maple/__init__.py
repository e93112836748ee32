"""MAPLE (Chen et al., NeurIPS 2021) and MOPO on RLlib's new API stack (docs/maple.md).

The torch/numpy parts (`ensemble`, `rollout`, `termination`, `segments`, `networks`, `losses`)
import no ray; the RLlib parts are imported lazily.
"""
