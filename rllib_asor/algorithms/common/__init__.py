"""Pieces every algorithm here shares: Learner speed-ups, pipeline placement, callbacks, faults;
and what the imitation-from-observation baselines share: state-only demonstrations
(`demonstrations`), the inverse dynamics model (`inverse_dynamics`, BCO and SOIL) and their
offline data and evaluation (`ifo_data`)."""
