"""Old RLlib YAML keys are translated to new-stack names, each with a warning."""

from __future__ import annotations

import pytest

from rllib_asor.cli import experiment
from rllib_asor.cli.errors import UsageError
from rllib_asor.cli.main import main

LEGACY = """
cartpole-legacy:
  env: CartPole-v1
  run: PPO
  stop: {episode_reward_mean: 150, timesteps_total: 100000, training_iteration: 7}
  config:
    framework: torch
    num_workers: 1
    num_sgd_iter: 4
    sgd_minibatch_size: 64
    train_batch_size: 512
    observation_filter: MeanStdFilter
    model: {fcnet_hiddens: [32, 16], fcnet_activation: tanh}
  checkpoint_freq: 3
"""


def test_legacy_config_keys_are_translated_to_new_stack_values(write_yaml):
    [exp] = experiment.load_file(write_yaml(LEGACY))
    cfg = experiment.validate(exp)
    assert cfg.num_env_runners == 1
    assert cfg.num_epochs == 4
    assert cfg.minibatch_size == 64
    assert cfg.train_batch_size_per_learner == 512
    assert cfg.model_config["fcnet_hiddens"] == [32, 16]
    assert cfg.model_config["fcnet_activation"] == "tanh"
    assert cfg._env_to_module_connector is not None  # MeanStdFilter connector
    assert exp.checkpoint_config == {"checkpoint_frequency": 3}


def test_legacy_stop_keys_are_translated_and_training_iteration_kept(write_yaml):
    [exp] = experiment.load_file(write_yaml(LEGACY))
    assert exp.stop == {
        "env_runners/episode_return_mean": 150,
        "num_env_steps_sampled_lifetime": 100000,
        "training_iteration": 7,
    }


def test_legacy_keys_produce_one_warning_each(write_yaml):
    path = write_yaml(LEGACY)
    [exp] = experiment.load_file(path)
    text = "\n".join(exp.warnings)
    for old, new in [
        ("num_workers", "num_env_runners"),
        ("num_sgd_iter", "num_epochs"),
        ("sgd_minibatch_size", "minibatch_size"),
        ("episode_reward_mean", "env_runners/episode_return_mean"),
        ("timesteps_total", "num_env_steps_sampled_lifetime"),
    ]:
        assert f"'{old}' translated to '{new}'" in text
    assert (
        "legacy key 'model' (fcnet_activation, fcnet_hiddens) translated to 'model_config'" in text
    )
    assert "observation_filter: MeanStdFilter" in text
    assert all(w.startswith(path) for w in exp.warnings)


def test_unreachable_address_fails_before_legacy_warnings_are_printed(write_yaml, capsys):
    rc = main(["train", "file", write_yaml(LEGACY), "--address", "127.0.0.1:1"])
    err = capsys.readouterr().err
    assert rc == 2
    assert "rllib: warning:" not in err  # bad input: one line only
    assert "127.0.0.1:1" in err


def test_framework_tf_runs_as_torch_and_an_unknown_framework_is_refused(write_yaml):
    path = write_yaml("x:\n  env: CartPole-v1\n  run: PPO\n  config: {framework: tf2}\n")
    [exp] = experiment.load_file(path)
    assert "framework" not in exp.config
    assert any("'framework: tf2' runs as torch" in w for w in exp.warnings)
    path = write_yaml("x:\n  env: CartPole-v1\n  run: PPO\n  config: {framework: jax}\n")
    with pytest.raises(UsageError, match=r"x\.config\.framework: framework 'jax' is invalid"):
        experiment.load_file(path)


def test_legacy_model_key_outside_default_model_config_is_refused(write_yaml):
    path = write_yaml(
        "x:\n  env: CartPole-v1\n  run: PPO\n  config: {model: {use_attention: true}}\n"
    )
    with pytest.raises(
        UsageError,
        match=r"x\.config\.model\.use_attention: unknown model setting; allowed: .*fcnet_hiddens",
    ):
        experiment.load_file(path)


def test_flags_build_the_same_experiment_as_yaml(write_yaml):
    flags = experiment.from_flags("PPO", "CartPole-v1", '{"num_workers": 1, "lr": 0.001}')
    [yaml_exp] = experiment.load_file(
        write_yaml("y:\n  env: CartPole-v1\n  run: PPO\n  config: {num_workers: 1, lr: 0.001}\n")
    )
    assert flags.config == yaml_exp.config == {"num_env_runners": 1, "lr": 0.001}
    assert flags.name == "PPO_CartPole-v1"


def test_rl_module_block_selects_a_registered_module_class(write_yaml):
    [exp] = experiment.load_file(
        write_yaml("""
        x:
          env: CartPole-v1
          run: PPO
          stop: {training_iteration: 2}
          config:
            rl_module: {module_class: race_net, model_config: {pi_hiddens: [64]}}
            model_config: {vf_hiddens: [32]}
    """)
    )
    cfg = experiment.build_algo_config(exp)
    assert cfg._rl_module_spec.module_class.__name__ == "RaceNetModule"
    assert cfg.model_config["pi_hiddens"] == [64] and cfg.model_config["vf_hiddens"] == [32]
    assert (
        experiment.param_space(exp, cfg)["_rl_module_spec"].module_class.__name__ == "RaceNetModule"
    )
    # Validation builds an env runner: the race network on CartPole is refused in one line.
    with pytest.raises(UsageError, match="env runner cannot be built.*RaceNetModule needs a Dict"):
        experiment.validate(exp)


def test_legacy_custom_model_becomes_rl_module_block(write_yaml):
    [exp] = experiment.load_file(
        write_yaml("""
        x:
          env: CartPole-v1
          run: PPO
          config: {model: {custom_model: race_net, custom_model_config: {pi_hiddens: [64]}}}
    """)
    )
    assert exp.config == {
        "rl_module": {"module_class": "race_net"},
        "model_config": {"pi_hiddens": [64]},
    }
    assert any("'model.custom_model: race_net' translated to 'rl_module" in w for w in exp.warnings)


def test_unknown_module_class_is_refused(write_yaml):
    [exp] = experiment.load_file(
        write_yaml(
            "x:\n  env: CartPole-v1\n  run: PPO\n  config: {rl_module: {module_class: nope_net}}\n"
        )
    )
    with pytest.raises(
        UsageError, match=r"x\.config\.rl_module\.module_class: .*allowed one of \['race_net'\]"
    ):
        experiment.validate(exp)
