"""MAPLE's and MOPO's settings as the paper's code ran them: the torch port's ensemble by default,
the TF MAPLE's as the named choice `ensemble: tf_maple`, MOPO's h and λ per dataset."""

from __future__ import annotations

import pytest

import rllib_asor
from rllib_asor.algorithms.maple.settings import MapleSettings, mopo_dataset_settings


def parts(task: str, quality: str | tuple[str, ...]) -> list[str]:
    qualities = (quality,) if isinstance(quality, str) else quality
    return [f"/d/{task}/{dyn}/{q}" for dyn in ("original", "body_mass") for q in qualities]


def test_default_ensemble_is_the_torch_ports_twenty_members_fourteen_elites_width_256():
    s = MapleSettings()
    assert (s.ensemble_members, s.ensemble_elites, s.ensemble_hidden) == (20, 14, 256)


def test_tf_maple_names_the_seven_five_two_hundred_ensemble_and_keys_beside_it_win():
    s = MapleSettings.from_dict({"ensemble": "tf_maple"})
    assert (s.ensemble_members, s.ensemble_elites, s.ensemble_hidden) == (7, 5, 200)
    s = MapleSettings.from_dict({"ensemble": "tf_maple", "ensemble_hidden": 64})
    assert (s.ensemble_members, s.ensemble_hidden) == (7, 64)
    cfg = rllib_asor.MapleConfig().maple(ensemble="tf_maple")
    assert cfg.settings.ensemble_members == 7 and "ensemble" not in cfg.maple_settings
    assert rllib_asor.MapleConfig().maple(ensemble="torch_port").settings.ensemble_elites == 14


def test_unknown_ensemble_preset_is_refused_in_one_line():
    with pytest.raises(
        ValueError, match=r"^maple.ensemble='tf' is invalid: allowed torch_port \| tf_maple$"
    ):
        MapleSettings.from_dict({"ensemble": "tf"})


@pytest.mark.parametrize(
    ("task", "quality", "horizon", "lam"),
    [
        ("hopper", "medium", 5, 5.0),
        ("walker2d", "medium-replay", 1, 1.0),
        ("halfcheetah", "medium", 1, 1.0),
        ("walker2d", ("medium", "expert"), 1, 2.0),
    ],
)
def test_mopo_takes_h_and_lambda_from_mopos_own_setting_for_the_dataset(
    task, quality, horizon, lam
):
    cfg = rllib_asor.MopoConfig().offline_data(input_=parts(task, quality))
    assert (cfg.settings.horizon, cfg.settings.penalty_coef) == (horizon, lam)
    assert cfg._model_config_auto_includes["maple"]["penalty_coef"] == lam


def test_mopo_keeps_what_the_user_set_and_falls_back_to_h5_lambda1_for_unknown_data():
    cfg = (
        rllib_asor.MopoConfig()
        .offline_data(input_=parts("hopper", "medium"))
        .maple(penalty_coef=2.0)
    )
    assert (cfg.settings.horizon, cfg.settings.penalty_coef) == (5, 2.0)
    again = rllib_asor.MopoConfig().update_from_dict(cfg.to_dict())
    assert again.settings.penalty_coef == 2.0
    plain = rllib_asor.MopoConfig().update_from_dict(
        rllib_asor.MopoConfig().offline_data(input_=parts("walker2d", "medium-replay")).to_dict()
    )
    assert plain.settings.horizon == 1
    assert mopo_dataset_settings(parts("ant", "medium")) == {}
    other = rllib_asor.MopoConfig().offline_data(input_=parts("ant", "medium"))
    assert (other.settings.horizon, other.settings.penalty_coef) == (5, 1.0)
