"""MAPLE's evaluation metrics are never NaN: without the dataset's reference returns the
normalized score is absent from the result (the returns stay)."""

from __future__ import annotations

from types import SimpleNamespace

from ray.rllib.utils.metrics.metrics_logger import MetricsLogger

from rllib_asor.algorithms.maple import maple


def test_a_score_without_reference_returns_is_absent_not_nan(monkeypatch) -> None:
    res = {
        "original": {"return_mean": 12.0, "return_std": 1.0, "normalized_score": float("nan")},
        "mean": {"return_mean": 12.0, "normalized_score": float("nan")},
    }
    monkeypatch.setattr(maple, "evaluate", lambda *a, **k: res)
    algo = SimpleNamespace(
        _manifest={}, _settings=SimpleNamespace(evaluation_episodes=1), metrics=MetricsLogger()
    )
    maple.MAPLE._evaluate(algo, SimpleNamespace(nets=None))
    logged = algo.metrics.reduce(compile=True)["evaluation"]
    assert logged["original/return_mean"] == 12.0 and logged["mean/return_mean"] == 12.0
    assert not any(k.endswith("normalized_score") for k in logged)
