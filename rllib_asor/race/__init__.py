"""The obstacle race on RLlib: its network and action distribution, PPO config and metrics,
map curriculum, and evaluation on unseen courses."""
