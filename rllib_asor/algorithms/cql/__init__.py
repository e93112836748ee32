"""CQL: offline inputs (our datasets) for RLlib's CQL; its fast module lives in `sac/fast.py`."""
