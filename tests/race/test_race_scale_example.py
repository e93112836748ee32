"""tuned_examples/race/ppo-asor-scale.yaml is ppo-asor.yaml with another layout: only the keys
of where and how much it samples and how the Learner cuts the batch differ, so a comparison of
the two at an equal env-step budget (studies/race_scale) compares layouts, not algorithms."""

from __future__ import annotations

from pathlib import Path

from rllib_asor.cli import experiment

REPO = Path(__file__).resolve().parents[2]
LAYOUT_KEYS = {
    "num_env_runners",
    "num_envs_per_env_runner",
    "num_cpus_per_env_runner",
    "train_batch_size",
    "minibatch_size",
    "num_learners",
    "num_gpus_per_learner",
}


def load(name: str) -> experiment.Experiment:
    [exp] = experiment.load_file(str(REPO / "tuned_examples/race" / name))
    return exp


def test_scale_example_differs_from_todays_only_in_its_layout():
    today, scale = load("ppo-asor.yaml"), load("ppo-asor-scale.yaml")
    assert (scale.env, scale.run, scale.stop, scale.asor) == (
        today.env,
        today.run,
        today.stop,
        today.asor,
    )
    differ = {
        k
        for k in today.config.keys() | scale.config.keys()
        if today.config.get(k) != scale.config.get(k)
    }
    assert differ <= LAYOUT_KEYS, differ - LAYOUT_KEYS


def test_scale_example_takes_1024_env_steps_per_runner_on_a_16_core_gpu_node():
    cfg = load("ppo-asor-scale.yaml").config
    assert cfg["train_batch_size"] == 1024 * cfg["num_env_runners"]
    assert cfg["train_batch_size"] % cfg["minibatch_size"] == 0
    assert cfg["num_gpus_per_learner"] == 1 and cfg["num_learners"] == 0
    # one core per runner, one for the Learner, one for the driver
    assert cfg["num_env_runners"] * cfg["num_cpus_per_env_runner"] + 2 <= 16
