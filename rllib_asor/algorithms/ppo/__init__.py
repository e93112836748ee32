"""PPO: lean Learner (bootstrap rows dropped) and overlapped sampling."""
