"""What a name stands for, in one place: env ids for RLlib and Tune (`envs`, `env_names`), what
the CLI knows about each env family (`families`), our algorithm run names (`algorithms`) and
the RLModule names a YAML can give (`models`)."""
