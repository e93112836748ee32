"""benchmarks/soak_cli.py: the traceback finder, the command list and a resumed run."""

from __future__ import annotations

import json

from benchmarks import soak_cli


def test_each_traceback_is_found_with_its_exception_line():
    text = (
        "rllib: x\nTraceback (most recent call last):\n  File \"a.py\", line 1, in f\n"
        "    g()\nSystemExit: 1\nmore\n(EnvRunner pid=9) Traceback (most recent call last):\n"
        "(EnvRunner pid=9)   File \"b.py\", line 2\n(EnvRunner pid=9) ValueError: bad\n"
    )
    assert soak_cli.tracebacks(text) == ["SystemExit: 1", "ValueError: bad"]
    assert soak_cli.tracebacks("rllib: x.stop.foo: not a metric PPO reports") == []


def test_tracebacks_ray_relays_in_colour_and_from_actors_with_a_repr_are_found():
    # as Ray printed them into a pipe: the prefix in ANSI colour, the trainable's
    # prefix its repr with parentheses of its own
    runner = "\x1b[36m(SingleAgentEnvRunner pid=21063)\x1b[0m "
    trainable = "\x1b[36m(AsorPPO(env=x; env-runners=2; multi-agent=False) pid=13779)\x1b[0m "
    text = "".join(
        prefix + line + "\n"
        for prefix in (runner, trainable)
        for line in (
            "Exception ignored in: <function EnvRunner.__del__ at 0x7f>",
            "Traceback (most recent call last):",
            '  File "ray/rllib/env/env_runner.py", line 212, in __del__',
            "SystemExit: 1",
        )
    )
    assert soak_cli.tracebacks(text) == ["SystemExit: 1", "SystemExit: 1"]
    frameless = "(X pid=3) Exception ignored in: <function f at 0x1>\n(X pid=3) SystemExit: 1\n"
    assert soak_cli.tracebacks(frameless) == ["SystemExit: 1"]


def test_every_tuned_example_and_ab_are_soaked():
    names = [n for n, _ in soak_cli.commands(None)]
    assert "lava__ppo-asor" in names and "race__ppo-asor" in names and names[-1].startswith("ab__")
    assert all(a[-1] == "--test" for _, a in soak_cli.commands(None))
    assert soak_cli.commands("no-such-file") == []


def test_a_finished_run_is_not_run_again(tmp_path):
    record = {"name": "n", "command": "rllib x", "exit": 1, "seconds": 1.0, "tracebacks": [],
              "clean": False}  # fmt: skip
    (tmp_path / "n.json").write_text(json.dumps(record))
    assert soak_cli.run_one("n", ["no-such-subcommand"], tmp_path, 5, tmp_path) == record
    summary = soak_cli.summarise([record, {**record, "exit": 0, "tracebacks": ["E: x"]}])
    assert summary["rllib x"] == {"runs": 2, "nonzero": 1, "with_traceback": 1, "seen": ["E: x"]}
