"""`--stop` parsing, `--test` overrides, grid_search expansion into the Tune param space."""

from __future__ import annotations

from pathlib import Path

import pytest

from rllib_asor.cli import cluster, experiment, grid
from rllib_asor.cli.errors import UsageError

REPO = Path(__file__).resolve().parents[2]


def test_stop_flags_parse_numbers_and_translate_legacy_names():
    stop = experiment.parse_stop_flags(
        ["training_iteration=10", "episode_reward_mean=150.5", "timesteps_total=1e5"]
    )
    assert stop == {
        "training_iteration": 10,
        "env_runners/episode_return_mean": 150.5,
        "num_env_steps_sampled_lifetime": 1e5,
    }


@pytest.mark.parametrize("item", ["training_iteration", "=3", "training_iteration=abc"])
def test_bad_stop_flag_is_refused(item):
    with pytest.raises(UsageError, match="--stop"):
        experiment.parse_stop_flags([item])


def test_cli_stop_overrides_file_stop(write_yaml):
    [exp] = experiment.load_file(
        write_yaml(
            "x:\n  env: CartPole-v1\n  run: PPO\n  stop: {training_iteration: 5, timesteps_total: 9}\n"
        )
    )
    experiment.apply_overrides(exp, stop={"training_iteration": 1})
    assert exp.stop == {"training_iteration": 1, "num_env_steps_sampled_lifetime": 9}


def test_test_mode_is_tiny_with_fractional_env_runners(write_yaml):
    [exp] = experiment.load_file(
        write_yaml(
            "x:\n  env: CartPole-v1\n  run: PPO\n  config: {train_batch_size: 4000, minibatch_size: 512}\n"
        )
    )
    experiment.apply_overrides(exp, test=True)
    cfg = experiment.validate(exp)
    assert cfg.num_env_runners == 2 and cfg.num_cpus_per_env_runner == 0.5
    assert cfg.train_batch_size_per_learner == experiment.TEST_BATCH
    assert cfg.minibatch_size <= cfg.train_batch_size_per_learner
    assert exp.stop == {"training_iteration": 2}
    assert experiment.required_cpus(cfg) <= 2


def test_test_mode_on_offline_data_reads_it_with_one_prelearner(write_yaml, tmp_path):
    """An offline `--test` run starts one OfflinePreLearner actor, not RLlib's 2, keeping the
    file's other Ray Data settings, and its Ray is sized for it."""
    data = tmp_path / "data"
    data.mkdir()
    path = write_yaml(
        "x:\n  env: Pendulum-v1\n  run: CQL\n  config:\n"
        f"    input: [{data}]\n    lr: null\n    map_batches_kwargs: {{num_cpus: 0.5}}\n"
    )
    [exp] = experiment.load_file(path)
    experiment.apply_overrides(exp, test=True)
    cfg = experiment.validate(exp)
    assert cfg.map_batches_kwargs == {"num_cpus": 0.5, "concurrency": 1}
    assert experiment.offline_data_cpus(cfg) == 1.5
    assert cfg.dataset_num_iters_per_learner == 2


def test_test_mode_puts_a_gpu_learner_on_the_cpu_when_torch_sees_no_cuda(write_yaml):
    """`ppo-asor-scale.yaml --test` on a laptop: the file's GPU Learner becomes a CPU Learner,
    with one warning naming the key (on a machine with CUDA the file's value stays)."""
    import torch

    path = write_yaml(
        "x:\n  env: CartPole-v1\n  run: PPO\n"
        "  config: {num_gpus_per_learner: 1, num_gpus_per_env_runner: 0.5}\n"
    )
    [exp] = experiment.load_file(path)
    experiment.apply_overrides(exp, test=True)
    if torch.cuda.is_available():
        assert exp.config["num_gpus_per_learner"] == 1 and not exp.warnings
        return
    assert exp.config["num_gpus_per_learner"] == exp.config["num_gpus_per_env_runner"] == 0
    assert any("num_gpus_per_learner: 1 -> 0 for --test" in w for w in exp.warnings)
    assert any("num_gpus_per_env_runner: 0.5 -> 0 for --test" in w for w in exp.warnings)
    config = experiment.validate(exp)
    assert config.num_gpus_per_learner == config.num_gpus_per_env_runner == 0


def test_num_env_runners_and_checkpoint_flags(write_yaml):
    path = write_yaml("x:\n  env: CartPole-v1\n  run: PPO\n  stop: {training_iteration: 2}\n")
    [exp] = experiment.load_file(path)
    experiment.apply_overrides(exp, num_env_runners=3, checkpoint_freq=4)
    assert experiment.validate(exp).num_env_runners == 3
    assert experiment.checkpoint_kwargs(exp) == {
        "num_to_keep": 3,
        "checkpoint_at_end": True,
        "checkpoint_frequency": 4,
    }


def test_grid_search_anywhere_becomes_tune_grid_in_param_space(write_yaml):
    [exp] = experiment.load_file(
        write_yaml("""
        x:
          env: CartPole-v1
          run: PPO
          stop: {training_iteration: 2}
          config:
            lr: {grid_search: [0.001, 0.0001]}
            lambda: {grid_search: [0.9, 0.95]}
            model_config: {fcnet_hiddens: {grid_search: [[32], [64, 64]]}}
            env_config: {}
            asor: {lambda_: {grid_search: [0.0, 0.1]}, mode: srpo}
    """)
    )
    space = experiment.param_space(exp, experiment.validate(exp))
    assert space["lr"] == {"grid_search": [0.001, 0.0001]}
    assert space["lambda"] == {"grid_search": [0.9, 0.95]}
    assert space["_model_config"]["fcnet_hiddens"] == {"grid_search": [[32], [64, 64]]}
    assert space["asor"] == {"lambda_": {"grid_search": [0.0, 0.1]}, "mode": "srpo"}
    assert exp.num_trials == 16


def test_lava_seed_sweep_expands_to_12_concrete_trials():
    from ray.tune.search.variant_generator import generate_variants

    [exp] = experiment.load_file(str(REPO / "tuned_examples/sweeps/lava-seeds.yaml"))
    space = experiment.param_space(exp, experiment.validate(exp))
    variants = [spec for _, spec in generate_variants(space)]
    assert len(variants) == exp.num_trials == 12
    combos = {(v["seed"], v["asor"]["mode"], v["asor"]["lambda_"]) for v in variants}
    assert len(combos) == 12
    assert all(not list(grid.find_grids(v)) for v in variants)  # all resolved
    assert {v["asor"]["mode"] for v in variants} == {"asor", "srpo"}


@pytest.mark.parametrize("name", ["ppo", "ppo-srpo", "ppo-asor"])
def test_lava_examples_validate(name):
    [exp] = experiment.load_file(str(REPO / f"tuned_examples/lava/{name}.yaml"))
    cfg = experiment.validate(exp)
    assert cfg.env == "rllib_asor/LavaWorld-v0"
    assert cfg.model_config["fcnet_hiddens"] == [64, 64]
    assert exp.stop == {"num_env_steps_sampled_lifetime": 150000}
    assert (exp.asor is None) == (name == "ppo")


@pytest.mark.parametrize(
    ("address", "target"),
    [
        ("10.0.0.1:6379", ("10.0.0.1", 6379)),
        ("ray://head:10001", ("head", 10001)),
        ("head", ("head", 6379)),
        ("auto", None),
    ],
)
def test_address_parsing(address, target):
    assert cluster.parse_address(address) == target


def test_bad_address_is_refused():
    with pytest.raises(UsageError, match="--address"):
        cluster.parse_address("host:notaport")
