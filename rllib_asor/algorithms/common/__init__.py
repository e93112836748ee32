"""Pieces every algorithm here shares: Learner speed-ups, pipeline placement, callbacks, faults."""
