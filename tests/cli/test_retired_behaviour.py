"""The retired keys of old RLlib files (`rllib_asor.cli.retired`) and the rest of
`legacy.translate_config`, each on its own: where the value lands, the one warning it gives
(naming the file), and the one-line error (naming file and key) for a value it cannot take
(each test aims at behaviour a mutation run showed untested)."""

from __future__ import annotations

import pytest

from rllib_asor.cli import legacy
from rllib_asor.cli.errors import UsageError

SRC = "old.yaml"


def _translate(config):
    out, warnings = legacy.translate_config(config, SRC)
    assert all(w.startswith(f"{SRC}: ") for w in warnings), warnings
    return out, warnings


def _refused(config, key, match=None):
    with pytest.raises(UsageError, match=match) as info:
        legacy.translate_config(config, SRC)
    assert (info.value.source, info.value.key) == (SRC, key)


# --- framework --------------------------------------------------------------------------------
def test_torch_frameworks_are_kept_quietly_or_with_one_dropped_warning():
    assert _translate({"framework": "torch"}) == ({}, [])
    assert _translate({"framework": None}) == ({}, [])
    assert _translate({"use_pytorch": True}) == (
        {},
        [f"{SRC}: legacy key 'use_pytorch: true' dropped: torch is the only framework"],
    )


def test_tf_frameworks_run_as_torch_with_a_warning_naming_the_setting():
    for config, shown in (({"use_pytorch": False}, "use_pytorch: false"),
                          ({"framework": "tf2"}, "framework: tf2")):
        out, warnings = _translate(config)
        assert out == {}
        assert len(warnings) == 1 and f"'{shown}' runs as torch" in warnings[0]
    _refused({"framework": "jax"}, "framework", "allowed torch | tf")


# --- replay settings --------------------------------------------------------------------------
@pytest.mark.parametrize("value, kind", [(True, "PrioritizedEpisodeReplayBuffer"),
                                         (False, "EpisodeReplayBuffer")])
def test_prioritized_replay_picks_the_buffer_type(value, kind):
    out, warnings = _translate({"prioritized_replay": value})
    assert out == {"replay_buffer_config": {"type": kind}}
    assert warnings == [
        f"{SRC}: legacy key 'prioritized_replay: {value}' translated to "
        f"'replay_buffer_config.type: {kind}'"
    ]


def test_top_level_replay_keys_land_in_the_replay_block_with_a_warning_each():
    out, warnings = _translate({"buffer_size": 5000, "prioritized_replay_alpha": 0.6})
    assert out == {"replay_buffer_config": {"capacity": 5000, "alpha": 0.6}}
    assert warnings == [
        f"{SRC}: legacy key 'buffer_size' translated to 'replay_buffer_config.capacity'",
        f"{SRC}: legacy key 'prioritized_replay_alpha' translated to 'replay_buffer_config.alpha'",
    ]


def test_the_replay_block_translates_types_and_keys_and_keeps_the_rest():
    out, warnings = _translate({"replay_buffer_config": {
        "type": "MultiAgentReplayBuffer", "prioritized_replay_beta": 0.4, "learning_starts": 99,
        "replay_mode": "independent", "capacity": 1000,
    }})
    assert out == {
        "replay_buffer_config": {"type": "EpisodeReplayBuffer", "beta": 0.4, "capacity": 1000},
        "num_steps_sampled_before_learning_starts": 99,
    }
    assert warnings == [
        f"{SRC}: replay buffer type 'MultiAgentReplayBuffer' translated to 'EpisodeReplayBuffer'",
        f"{SRC}: 'replay_buffer_config.prioritized_replay_beta' translated to "
        "'replay_buffer_config.beta'",
        f"{SRC}: 'replay_buffer_config.learning_starts' translated to "
        "'num_steps_sampled_before_learning_starts'",
        f"{SRC}: 'replay_buffer_config.replay_mode' dropped: no effect on the new API stack",
    ]
    own = {"type": "my_pkg.buffers:MyBuffer"}  # a type that is not an old RLlib name
    assert _translate({"replay_buffer_config": own}) == ({"replay_buffer_config": own}, [])


# --- optimization and SAC's per-network models -------------------------------------------------
def test_the_optimization_block_takes_only_its_three_learning_rates():
    out, warnings = _translate({"optimization": {"actor_learning_rate": 0.1}})
    assert out == {"actor_lr": 0.1} and len(warnings) == 1
    for bad in (None, ["actor_learning_rate"], {"actor_learning_rate": 0.1, "lr": 1}):
        _refused({"optimization": bad}, "optimization", "allowed a mapping with actor_learning_rate")


def test_sac_network_blocks_keep_their_layers_and_say_what_they_drop():
    out, warnings = _translate({"Q_model": {"fcnet_hiddens": [8], "custom_model": "x"}})
    assert out == {"model_config": {"fcnet_hiddens": [8]}}
    assert warnings == [
        f"{SRC}: legacy key 'Q_model' translated to 'model_config' (fcnet_hiddens, "
        "fcnet_activation) (custom_model dropped: no new-stack meaning)"
    ]
    out, warnings = _translate({"policy_model": {"fcnet_activation": "relu"}})
    assert warnings == [
        f"{SRC}: legacy key 'policy_model' translated to 'model_config' (fcnet_hiddens, "
        "fcnet_activation)"
    ]
    _, warnings = _translate({"Q_model": {"free_log_std": True, "custom_model": "x"}})
    assert warnings[0].endswith("(custom_model, free_log_std dropped: no new-stack meaning)")
    _, warnings = _translate({"Q_model": {"fcnet_hiddens": [8]}, "policy_model": {"fcnet_hiddens": [4]}})
    assert any("SAC uses one model_config for policy and critics; kept '[8]'" in w for w in warnings)
    _refused({"Q_model": "fcnet"}, "Q_model", "allowed a mapping of model settings")


# --- the rest of translate_config --------------------------------------------------------------
def test_horizon_goes_to_env_config_unless_the_file_sets_the_limit_itself():
    assert _translate({"horizon": 50, "env_config": {"a": 1}})[0] == {
        "env_config": {"max_episode_steps": 50, "a": 1}
    }
    assert _translate({"horizon": 50, "env_config": {"max_episode_steps": 9}})[0] == {
        "env_config": {"max_episode_steps": 9}
    }


def test_the_mean_std_filter_warning_names_the_connector():
    _, warnings = _translate({"observation_filter": "MeanStdFilter"})
    assert warnings == [
        f"{SRC}: legacy key 'observation_filter: MeanStdFilter' translated to a MeanStdFilter "
        "env-to-module connector"
    ]


def test_errors_name_the_file_and_the_key_as_written():
    _refused({"observation_filter": "Clip"}, "observation_filter")
    _refused({"rl_module": "race_net"}, "rl_module", "module_class")
    with pytest.raises(UsageError) as info:
        legacy.translate_config({"model": {"fcnet_hidens": [8]}}, SRC)
    assert (info.value.source, info.value.key) == (SRC, "model.fcnet_hidens")
    with pytest.raises(UsageError) as info:
        legacy.translate_stop({"episode_reward_mean": "high"}, SRC)
    assert (info.value.source, info.value.key) == (SRC, "stop.episode_reward_mean")


def test_moved_class_paths_inside_lists_and_mappings_warn_naming_the_file():
    old, new = next(iter(legacy.MOVED_MODULES.items()))
    out, warnings = _translate({"a": {"b": [f"{old}:X"]}})
    assert out == {"a": {"b": [f"{new}:X"]}}
    assert warnings == [f"{SRC}: class path '{old}:X' moved to '{new}:X'"]


def test_an_empty_or_null_model_config_block_adds_nothing():
    assert _translate({"model_config": None, "lr": 0.1}) == ({"lr": 0.1}, [])
    assert _translate({"model_config": {}}) == ({}, [])
    assert _translate({"model_config": {"fcnet_hiddens": [4]}}) == (
        {"model_config": {"fcnet_hiddens": [4]}}, []
    )
