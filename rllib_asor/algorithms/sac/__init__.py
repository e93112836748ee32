"""SAC: the fast off-policy path (module, flat replay buffer, Learner); CQL reuses it."""
