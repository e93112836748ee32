"""Evaluating trained policies (the race on unseen courses, GIFs)."""
