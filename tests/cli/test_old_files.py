"""Old RLlib experiment files (tests/cli/old_files/, written in the style of Ray 1.x-2.9's tuned
examples) run as written: every retired key is translated to its new home or dropped, with one
warning each, and the value lands in the new-stack config."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from rllib_asor.cli import experiment, retired
from rllib_asor.cli.errors import UsageError
from tests.cli.test_e2e import run_cli

pytestmark = pytest.mark.heavy  # starts Ray or a subprocess: scheduled first (conftest)

OLD = Path(__file__).parent / "old_files"
RLLIB = str(Path(sys.executable).with_name("rllib"))


def _validated(name: str):
    """The file's experiment validated as `rllib train` would; a file without `stop:` (our
    fragments of old files) with `--stop training_iteration=1`, as it must be run now."""
    [exp] = experiment.load_file(str(OLD / name))
    experiment.apply_overrides(exp, stop=None if exp.stop else {"training_iteration": 1})
    return exp, experiment.validate(exp)


def _warned(exp, *fragments: str) -> None:
    hits = [w for w in exp.warnings if all(f in w for f in fragments)]
    assert len(hits) == 1, (fragments, exp.warnings)


def test_every_retired_key_is_covered_by_an_old_file():
    keys: set[str] = set()
    for path in OLD.glob("*.yaml"):
        for spec in yaml.safe_load(path.read_text()).values():
            config = spec.get("config") or {}
            keys |= set(config) | set(config.get("replay_buffer_config") or {})
    wanted = set(retired.RETIRED_KEYS) | set(retired.REPLAY_KEYS) | set(retired.REPLAY_LEARNING_STARTS)
    assert wanted <= keys, sorted(wanted - keys)


def test_old_ppo_file_framework_tf_old_gym_id_horizon_and_dropped_keys():
    exp, cfg = _validated("ppo-tf.yaml")
    assert cfg.framework_str == "torch"
    _warned(exp, "'framework: tf' runs as torch", "numbers will differ from a tf run")
    assert exp.env == cfg.env == "Pendulum-v1"
    _warned(exp, "env id 'Pendulum-v0' translated to 'Pendulum-v1'")
    assert cfg.env_config["max_episode_steps"] == 150
    _warned(exp, "'horizon: 150' translated to 'env_config.max_episode_steps'")
    assert (cfg.num_env_runners, cfg.num_envs_per_env_runner) == (1, 2)
    assert (cfg.num_epochs, cfg.minibatch_size, cfg.train_batch_size) == (3, 64, 256)
    assert cfg.model_config["fcnet_hiddens"] == [32, 32]
    assert cfg.model_config["fcnet_activation"] == "tanh"
    assert cfg.model_config["vf_share_layers"] is True
    assert cfg._env_to_module_connector is not None  # MeanStdFilter
    for key in ("enable_connectors", "num_accs", "soft_horizon", "num_gpus"):
        _warned(exp, f"legacy key '{key}' dropped: no effect")
    assert exp.stop == {
        "env_runners/episode_return_mean": -500,
        "num_env_steps_sampled_lifetime": 400000,
    }


def test_old_sac_file_models_optimization_and_replay_keys_land_in_the_new_config():
    exp, cfg = _validated("sac-old.yaml")
    _warned(exp, "'framework: tfe' runs as torch")
    assert cfg.env == "Pendulum-v1" and cfg.env_config["max_episode_steps"] == 200
    assert cfg.model_config["fcnet_hiddens"] == [64, 64]
    assert cfg.model_config["fcnet_activation"] == "relu"
    assert (cfg.actor_lr, cfg.critic_lr, cfg.alpha_lr) == (0.0004, 0.0005, 0.0006)
    rb = cfg.replay_buffer_config
    assert rb["type"] == "PrioritizedEpisodeReplayBuffer"
    assert (rb["alpha"], rb["beta"], rb["capacity"]) == (0.7, 0.5, 50000)
    assert cfg.num_steps_sampled_before_learning_starts == 256
    assert cfg.min_sample_timesteps_per_iteration == 500
    for key in ("prioritized_replay_eps", "worker_side_prioritization", "no_done_at_end"):
        _warned(exp, f"legacy key '{key}' dropped")
    _warned(exp, "'optimization.actor_learning_rate' translated to 'actor_lr'")


def test_old_sac_replay_block_and_differing_networks():
    exp, cfg = _validated("sac-replay-block.yaml")
    assert cfg.env == "HalfCheetah-v5"  # v3 needs mujoco-py, which gymnasium dropped
    assert cfg.model_config["fcnet_hiddens"] == [128, 128]  # the first block's, with a warning
    _warned(exp, "policy_model_config.fcnet_hiddens: [64, 64]", "one model_config")
    rb = cfg.replay_buffer_config
    assert (rb["type"], rb["alpha"], rb["beta"]) == ("PrioritizedEpisodeReplayBuffer", 0.6, 0.4)
    assert "prioritized_replay_eps" not in rb and "worker_side_prioritization" not in rb
    assert cfg.num_steps_sampled_before_learning_starts == 1000
    assert cfg.metrics_num_episodes_for_smoothing == 5


def test_use_pytorch_false_grid_search_and_tf_only_keys():
    exp, cfg = _validated("ppo-grid-pytorch-false.yaml")
    _warned(exp, "'use_pytorch: false' runs as torch")
    assert cfg.env == "CartPole-v0" and exp.num_trials == 2
    for key in ("eager_tracing", "simple_optimizer"):
        _warned(exp, f"legacy key '{key}' dropped")


def test_rllib_example_env_under_its_old_module_path_and_an_lstm_model():
    exp, cfg = _validated("ppo-env-class-path.yaml")
    assert cfg.model_config["use_lstm"] is True and cfg.model_config["lstm_cell_size"] == 16


def test_retired_keys_without_meaning_are_dropped_each_with_its_reason():
    exp, _ = _validated("ppo-retired-misc.yaml")
    keys = ("_disable_preprocessor_api", "_fake_gpus", "replay_sequence_length", "replay_burn_in",
            "replay_zero_init_states", "replay_mode", "storage_unit", "replay_batch_size")
    for key in keys:
        assert any(f"'{key}' dropped" in w for w in exp.warnings), (key, exp.warnings)


def test_appo_vtrace_false_is_refused_with_what_to_change():
    with pytest.raises(UsageError, match="vtrace: false is not supported.*run: PPO"):
        _validated("appo-vtrace-off.yaml")


def test_dry_run_prints_the_new_stack_yaml_without_ray(tmp_path):
    proc = subprocess.run(
        [RLLIB, "train", "file", str(OLD / "sac-old.yaml"), "--dry-run"],
        capture_output=True, text=True, timeout=120,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "'framework: tfe' runs as torch" in proc.stderr
    assert "Started a local Ray" not in proc.stderr + proc.stdout
    spec = yaml.safe_load(proc.stdout)["pendulum-sac-old"]
    assert spec["env"] == "Pendulum-v1" and spec["config"]["actor_lr"] == 0.0004
    saved = tmp_path / "new.yaml"  # the printed file runs without a single translation
    saved.write_text(proc.stdout)
    again = run_cli(["train", "file", str(saved), "--dry-run"])  # in this process: RLlib loaded
    assert again.rc == 0, again.err[-2000:]
    assert "translated" not in again.err and "dropped" not in again.err
    assert yaml.safe_load(again.out)["pendulum-sac-old"] == spec


@pytest.mark.slow  # ~1-5 min; the dry-run tests above build the same env runner
def test_old_sac_file_trains_with_test(tmp_path):
    proc = subprocess.run(
        [RLLIB, "train", "file", str(OLD / "sac-old.yaml"), "--test", "--storage-path",
         str(tmp_path)],
        capture_output=True, text=True, timeout=400,
    )
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    assert "1 trial(s), 0 errored" in proc.stdout


def test_rays_pendulum_sac_n_step_3_with_fragment_1_runs_as_old_rllib_ran_it():
    """Old RLlib raised `rollout_fragment_length` to `n_step` (DQN's validate_config; SAC's
    from Ray 1.10); RLlib 2.60 refuses the shorter fragment: translated, with one line."""
    exp, cfg = _validated("pendulum-sac.yaml")
    assert (cfg.n_step, cfg.rollout_fragment_length) == (3, 3)
    _warned(exp, "'rollout_fragment_length: 1' translated to 'rollout_fragment_length: 3'",
            "n_step: 3", "old RLlib")  # fmt: skip
    assert cfg.model_config["fcnet_hiddens"] == [256, 256]
    assert exp.stop == {
        "env_runners/episode_return_mean": -150,
        "num_env_steps_sampled_lifetime": 30000,
    }


def test_rays_pendulum_sac_passes_the_test_run_checks():
    """`rllib train file pendulum-sac.yaml --test` as far as Ray's start (no Ray here)."""
    result = run_cli(["train", "file", str(OLD / "pendulum-sac.yaml"), "--test", "--dry-run"])
    assert result.rc == 0, result.err[-2000:]
    assert "'rollout_fragment_length: 1' translated" in result.err


def test_sac_with_n_step_3_is_not_said_to_run_on_the_whole_fast_path():
    """n_step 3 keeps RLlib's replay and Learner: the note says only the critics are fast."""
    proc = subprocess.run(  # a fresh process: the note is said once per process
        [RLLIB, "train", "file", str(OLD / "pendulum-sac.yaml"), "--test", "--dry-run"],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "run: SAC gets the fast path's critics only" in proc.stderr
    assert "n_step 3" in proc.stderr and "runs on the fast off-policy path" not in proc.stderr
