"""`rllib evaluate` uses `rllib ab`'s evaluation seed by default and prints the seed it used."""

from __future__ import annotations

import argparse

from rllib_asor.cli import ab, evaluate


def _parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    evaluate.add_arguments(parser)
    return parser.parse_args(argv)


def test_default_seed_is_rllib_abs_evaluation_seed() -> None:
    assert evaluate.EVAL_SEED == ab.EVAL_SEED
    assert _parse(["ckpt"]).seed == ab.EVAL_SEED
    assert _parse(["ckpt", "--seed", "7"]).seed == 7


def test_the_printed_summary_names_the_seed(capsys) -> None:
    stats = {
        "checkpoint": "c", "env": "E", "episodes": 1, "explore": False, "return_mean": 1.0,
        "return_std": 0.0, "return_min": 1.0, "return_max": 1.0, "returns": [1.0],
        "lengths": [3], "per_dynamics": {}, "episode_metrics": {}, "seed": evaluate.EVAL_SEED,
    }  # fmt: skip
    evaluate._print(stats)
    assert (
        "seed: 1000000 (the default: the seed rllib ab evaluates with)" in capsys.readouterr().out
    )
    evaluate._print(dict(stats, seed=7))
    assert "seed: 7\n" in capsys.readouterr().out
