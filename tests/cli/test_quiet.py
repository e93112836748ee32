"""Known-harmless Ray/RLlib lines are dropped, everything else is kept, `--verbose` keeps all."""

from __future__ import annotations

import logging

from rllib_asor.cli import quiet

CORE_WORKER = (
    "[2026-11-23 20:10:05,221 E 2309 2309] core_worker.cc:2465: Actor with class name: "
    "'SingleAgentEnvRunner' and ID: 'fb99' has constructor arguments in the object store and "
    "max_restarts > 0. If the arguments in the object store go out of scope or are lost, ..."
)


def test_worker_lines_drop_only_known_harmless_ones():
    seen = []
    emit = quiet._filtered(seen.append)
    emit(
        {
            "lines": [
                CORE_WORKER,
                "ValueError: my env broke",
                "Install gputil for GPU system monitoring.",
            ]
        }
    )
    emit(
        {"lines": ["Checkpoint successfully created at: Checkpoint(...)"]}
    )  # nothing left: no call
    assert [d["lines"] for d in seen] == [["ValueError: my env broke"]]
    assert quiet._filtered(emit) is emit  # wrapping twice is a no-op


def test_driver_logger_filter_and_verbose_switch(monkeypatch, caplog):
    monkeypatch.delenv(quiet.VERBOSE_ENV, raising=False)
    quiet.quiet_driver()
    logger = logging.getLogger("ray")
    assert any(isinstance(f, quiet._DropHarmless) for f in logger.filters)
    record = logging.LogRecord(
        "ray", logging.WARNING, __file__, 1, "Token authentication is enabled", None, None
    )
    assert not quiet._DropHarmless().filter(record)
    record.msg = "a real problem"
    assert quiet._DropHarmless().filter(record)
    monkeypatch.setenv(quiet.VERBOSE_ENV, "1")
    assert quiet.verbose()
    seen = []
    handlers = [("ray_print_logs", seen.append)]
    from ray._private.ray_logging import global_worker_stdstream_dispatcher as dispatcher

    monkeypatch.setattr(dispatcher, "handlers", handlers)
    quiet.quiet_worker_lines()  # verbose: left as it is
    assert dispatcher.handlers[0][1] == seen.append


def _gym_override_warning_lines() -> list[str]:
    """The lines an env runner prints when RLlib registers its env id again: gymnasium's real
    warning, formatted as Python prints it (the message, then the source line)."""
    import warnings

    import gymnasium as gym

    env_id = "rllib-single-agent-env-v0"
    earlier = gym.registry.pop(env_id, None)  # an env runner built earlier in this process
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            gym.register(env_id, entry_point="gymnasium.envs.classic_control:CartPoleEnv")
            gym.register(env_id, entry_point="gymnasium.envs.classic_control:CartPoleEnv")
    finally:
        gym.registry.pop(env_id, None)
        if earlier is not None:
            gym.registry[env_id] = earlier
    (w,) = [w for w in caught if "Overriding environment" in str(w.message)]
    return warnings.formatwarning(w.message, w.category, w.filename, w.lineno).splitlines()


def test_gymnasiums_env_override_warning_is_dropped_from_workers_and_driver(monkeypatch):
    import warnings

    lines = _gym_override_warning_lines()
    assert len(lines) == 2 and "Overriding environment rllib-single-agent-env-v0" in lines[0]
    seen = []
    quiet._filtered(seen.append)({"lines": [*lines, "UserWarning: WARN: something else"]})
    assert seen == [{"lines": ["UserWarning: WARN: something else"]}]

    monkeypatch.delenv(quiet.VERBOSE_ENV, raising=False)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        quiet.quiet_driver()
        warnings.warn("\x1b[33mWARN: Overriding environment rllib-single-agent-env-v0 "
                      "already in registry.\x1b[0m", UserWarning, stacklevel=1)  # fmt: skip
        warnings.warn("WARN: Overriding environment MyEnv-v0 already in registry.", stacklevel=1)
    messages = [str(w.message) for w in caught]
    assert not any("rllib-single-agent-env-v0" in m for m in messages)
    assert any("MyEnv-v0" in m for m in messages)  # a user's own override still shows
