"""`AsorConfig`, setting by setting: the documented defaults and presets, every
boundary of every validated setting (the value just inside is taken, the one just outside is
refused with a message naming key, value and what is allowed), the λ forms, `from_dict`'s
alias and hints, and the helpers the rest of the package reads."""

from __future__ import annotations

import math

import pytest

from rllib_asor.asor.config import AsorConfig, field_docs, settings_help

DEFAULTS = {  # docs/algorithm.md; preset-independent
    "preset": "robust", "bonus_clip": 3.0, "logit_clip": 5.0, "archive_size": 4096,
    "rho_value": 0.5, "rho_count": 0.5, "mode": "asor", "proxy": "rnd", "log_omega_min": -5.0,
    "disc_hiddens": [256, 256, 256], "label_smoothing": 0.0, "aux_epochs": None,
    "rnd_hiddens": [128, 128], "rnd_embedding_dim": 64, "rnd_lr": 1e-3, "dynamics_buckets": 16,
    "ensemble_size": 5, "lambda_target": 0.1, "lambda_lr": 0.01, "lambda_max": 1.0,
    "lambda_init": 0.0, "lambda_kp": 0.0, "obs_keys": None, "seed": None,
}
ROBUST = {
    "lambda_": 0.05, "lambda_relative": True, "lambda_warmup": True, "shaping": "potential",
    "reward_form": "logit", "bonus_norm": "batch", "real_source": "archive", "disc_lr": 3e-4,
    "disc_grad_penalty": 5.0, "disc_logit_reg": 0.01, "disc_weight_decay": 1e-4,
    "disc_input_norm": True, "bonus_share_max": 0.2,
}
PAPER = {
    "lambda_": 0.01, "lambda_relative": False, "lambda_warmup": False, "shaping": "direct",
    "reward_form": "log", "bonus_norm": "off", "real_source": "batch", "disc_lr": 1e-3,
    "disc_grad_penalty": 0.0, "disc_logit_reg": 0.0, "disc_weight_decay": 0.0,
    "disc_input_norm": False, "bonus_share_max": 0.0,
}


def test_the_defaults_and_both_presets_are_the_documented_values():
    robust, paper = AsorConfig().to_dict(), AsorConfig(preset="paper").to_dict()
    assert robust == {**DEFAULTS, **ROBUST}
    assert paper == {**DEFAULTS, **PAPER, "preset": "paper"}
    assert type(robust["lambda_"]) is float


def test_a_setting_given_explicitly_wins_over_the_preset():
    cfg = AsorConfig(preset="paper", reward_form="gail", lambda_warmup=True, disc_lr=0.5)
    assert (cfg.reward_form, cfg.lambda_warmup, cfg.disc_lr) == ("gail", True, 0.5)
    assert cfg.bonus_norm == "off"


# (key, values taken, values refused, the allowed text)
BOUNDS = [
    ("rho_value", [1e-9, 1.0, 1], [0.0, 1.0001, -0.5, True, math.nan, "0.5"], "a number in (0, 1]"),
    ("rho_count", [1e-9, 1.0], [0.0, 1.0001, math.inf], "a number in (0, 1]"),
    ("mode", ["asor", "srpo", "count", "random"], ["ASOR", "ppo", None], "asor | srpo | count | random"),
    ("proxy", ["rnd", "ensemble", "rnd_per_dynamics"], ["RND", "count"], "rnd | ensemble | rnd_per_dynamics"),
    ("reward_form", ["log", "centered", "gail", "logit"], ["Log", "airl"], "log | centered | gail | logit"),
    ("real_source", ["batch", "archive"], ["buffer"], "batch | archive"),
    ("shaping", ["direct", "potential"], ["pbrs"], "direct | potential"),
    ("bonus_norm", ["running", "batch", "off"], ["none", False], "running | batch | off"),
    ("log_omega_min", [-1e-9, -999999.0], [0.0, -1e6, 1.0, math.nan, "x"], "a finite number < 0"),
    ("disc_lr", [1e-12], [0.0, -1.0, math.inf], "a number > 0"),
    ("rnd_lr", [1e-12], [0.0], "a number > 0"),
    ("lambda_lr", [1e-12], [0.0], "a number > 0"),
    ("bonus_clip", [1e-12], [0.0], "a number > 0"),
    ("logit_clip", [1e-12], [0.0, True], "a number > 0"),
    ("disc_grad_penalty", [0.0, 2], [-1e-9, math.inf], "a finite number ≥ 0"),
    ("disc_logit_reg", [0.0], [-1e-9], "a finite number ≥ 0"),
    ("disc_weight_decay", [0.0], [-1e-9], "a finite number ≥ 0"),
    ("lambda_relative", [True, False], [1, "yes"], "true or false"),
    ("lambda_warmup", [True, False], [0], "true or false"),
    ("disc_input_norm", [True, False], ["true"], "true or false"),
    ("aux_epochs", [None, 1e-9, 100], [0, 100.5, -1, math.nan, True], "a number in (0, 100] or null"),
    ("label_smoothing", [0.0, 0.4999], [0.5, -1e-9, math.nan], "a number in [0, 0.5)"),
    ("disc_hiddens", [[1], (4, 2)], [[], [0], [4, -1], [4.0], [True], "64", 64, None],
     "a non-empty list of positive integers"),
    ("rnd_hiddens", [[1]], [[], [0]], "a non-empty list of positive integers"),
    ("rnd_embedding_dim", [1], [0, 1.0, True], "an integer ≥ 1"),
    ("dynamics_buckets", [1], [0], "an integer ≥ 1"),
    ("archive_size", [1], [0, "8"], "an integer ≥ 1"),
    ("ensemble_size", [2], [1, 2.0, False], "an integer ≥ 2"),
    ("lambda_target", [0.0], [-1e-9, math.inf], "a finite number ≥ 0"),
    ("lambda_max", [0.0], [-1e-9], "a finite number ≥ 0"),
    ("lambda_init", [0.0], [-1e-9], "a finite number ≥ 0"),
    ("lambda_kp", [0.0], [-1e-9], "a finite number ≥ 0"),
    ("bonus_share_max", [0.0], [-1e-9], "a finite number ≥ 0"),
    ("obs_keys", [None, ["agent"], ("a", "b")], ["agent", [], [1], 5], "null or a non-empty list"),
    ("seed", [None, 0, -3], [1.0, True, "1"], "null or an integer"),
]


@pytest.mark.parametrize("key, good, bad, allowed", BOUNDS, ids=[b[0] for b in BOUNDS])
def test_each_setting_takes_its_range_and_refuses_just_outside_it(key, good, bad, allowed):
    for value in good:
        cfg = AsorConfig(**{key: value})
        expected = list(value) if isinstance(value, tuple) else value  # lists are stored as lists
        assert getattr(cfg, key) == expected
    for value in bad:
        with pytest.raises(ValueError) as info:
            AsorConfig(**{key: value})
        message = str(info.value)
        assert message.startswith(f"asor.{key}={value!r} is invalid: allowed {allowed}"), message


def test_hidden_layer_lists_are_stored_as_lists():
    cfg = AsorConfig(disc_hiddens=(8, 4), rnd_hiddens=(2,))
    assert cfg.disc_hiddens == [8, 4] and type(cfg.disc_hiddens) is list
    assert type(cfg.rnd_hiddens) is list


def test_lambda_takes_a_number_auto_or_an_increasing_schedule():
    assert AsorConfig(lambda_=0).lambda_ == 0.0 and type(AsorConfig(lambda_=2).lambda_) is float
    assert AsorConfig(lambda_="auto").lambda_ == "auto"
    schedule = AsorConfig(lambda_=[[0, 1], [10, 0]]).lambda_
    assert schedule == [[0.0, 1.0], [10.0, 0.0]] and all(type(x) is float for p in schedule for x in p)
    assert AsorConfig(lambda_=((5, 0.5),)).lambda_ == [[5.0, 0.5]]
    refused = ["Auto", -0.1, [], [[0, 1], [0, 2]], [[5, 1], [2, 1]], [[-1, 1]], [[0, -1]],
               [[0, 1, 2]], [[0]], [[0, "x"]], [5], "0.1", [[0, math.inf]]]
    for lam in refused:
        with pytest.raises(ValueError) as info:
            AsorConfig(lambda_=lam)
        assert str(info.value).startswith(f"asor.lambda_={lam!r} is invalid: allowed a number ≥ 0"), lam


def test_an_unknown_preset_is_refused_naming_both_presets():
    with pytest.raises(ValueError, match=r"asor\.preset='fast' is invalid: allowed robust \| paper"):
        AsorConfig(preset="fast")


def test_from_dict_takes_the_lambda_alias_and_names_unknown_keys_with_a_hint():
    assert AsorConfig.from_dict({"lambda": 0.2}).lambda_ == 0.2
    assert AsorConfig.from_dict(None) == AsorConfig()
    with pytest.raises(ValueError, match="either 'lambda' or 'lambda_', not both"):
        AsorConfig.from_dict({"lambda": 0.2, "lambda_": 0.3})
    with pytest.raises(ValueError) as info:
        AsorConfig.from_dict({"rho_valu": 0.3, "zzz": 1})
    message = str(info.value)
    assert "unknown key(s) 'rho_valu' (did you mean 'rho_value'?), 'zzz'; allowed: " in message
    assert "'zzz' (did you mean" not in message and "allowed: archive_size, aux_epochs, " in message
    cfg = AsorConfig(preset="paper", mode="srpo", lambda_=[[0, 1]], obs_keys=["a"])
    assert AsorConfig.from_dict(cfg.to_dict()) == cfg


def test_effective_rhos_and_whether_a_proxy_is_needed_per_mode():
    expect = {"asor": ((0.3, 0.6), True), "srpo": ((0.3, 1.0), False),
              "count": ((1.0, 0.6), True), "random": ((0.3, 0.6), False)}
    for mode, (rhos, proxy) in expect.items():
        cfg = AsorConfig(mode=mode, rho_value=0.3, rho_count=0.6)
        assert (cfg.effective_rhos, cfg.needs_proxy) == (rhos, proxy), mode


def test_every_setting_has_its_doc_and_help_shows_both_defaults():
    docs = field_docs()
    assert list(docs) == list(AsorConfig().to_dict())
    assert all(docs.values())
    assert docs["mode"].startswith("asor") or "asor" in docs["mode"]
    # a docstring over several lines is one line of single spaces
    assert "λ_I the dual-ascent (integral) term" in docs["lambda_kp"]
    assert not any("\n" in d or "  " in d for d in docs.values())
    text = settings_help()
    assert text.splitlines()[0] == "Settings (robust default | paper preset where they differ):"
    assert "    lambda_ = 0.05 | paper 0.01\n" in text
    assert "    mode = 'asor'\n" in text
