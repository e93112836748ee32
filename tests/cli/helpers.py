"""Several `rllib` commands in one fresh interpreter: one Python + Ray + RLlib start-up (about
5 s on 2 cores) instead of one per command, for the commands that only fail."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

# What the `rllib` console script does (`sys.exit(main())`), per command, in one process. `-P`
# keeps the current folder off sys.path, as for the console script: whatever imports from it
# is the CLI's doing. Each command's stdout and stderr are captured apart; output that bypasses
# sys.stdout/sys.stderr (a handler bound to the real stream, C code) lands in the process's own.
DRIVER = """
import contextlib, io, json, sys
from rllib_asor.cli.main import main
results = []
for argv in json.loads(sys.argv[1]):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = main(argv)
        except SystemExit as e:
            rc = e.code
    results.append({"returncode": rc, "stdout": out.getvalue(), "stderr": err.getvalue()})
print(json.dumps(results))
"""


def rllib_commands(
    commands: list[list[str]], env: dict[str, str], cwd: Path, timeout: int = 300
) -> list[SimpleNamespace]:
    """Run `rllib ARGS` for each ARGS in one interpreter started in `cwd` with `env`: a
    `returncode`, `stdout` and `stderr` per command, and nothing else on the process's stderr.

    A module imported stays imported for the next commands: only the last command may import
    the user's module (the earlier ones must fail before they would import it).
    """
    proc = subprocess.run(
        [sys.executable, "-P", "-c", DRIVER, json.dumps(commands)],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env,
        cwd=cwd,
    )
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    assert proc.stderr == "", proc.stderr[-3000:]
    return [SimpleNamespace(**r) for r in json.loads(proc.stdout.strip().splitlines()[-1])]
