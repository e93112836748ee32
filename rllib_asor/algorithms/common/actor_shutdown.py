"""RLlib's actor managers stop their actors synchronously: dead before `stop()` returns.

The cause of the `(SingleAgentEnvRunner pid=…) Exception ignored in: <function
EnvRunner.__del__> … SystemExit: 1` traceback at the end of a Tune trial,
read off Ray's own logs of runs that printed it:

1. `Algorithm.cleanup` -> `EnvRunnerGroup.stop()` -> `FaultTolerantActorManager.clear()`
   (ray/rllib/utils/actor_manager.py, `clear`) calls `ray.kill(actor)` and drops the handles at
   once. Both reach the GCS on separate channels: the kill as a force kill, the dropped
   handles as "actor has no references", a *graceful* destroy (`force_kill=0`,
   gcs_actor_manager.cc). Under load the graceful one sometimes arrives first and wins;
   the runner then exits the slow way, running Python teardown (`EnvRunner.__del__`).
2. `clear()` and with it `Trainable.stop()` return at once; Tune then frees the trial's
   placement group, and the raylet sends SIGTERM to every worker still in it ("DisconnectClient:
   sending SIGTERM to pgid=…", node_manager.cc), SIGKILL 200 ms later.
3. Ray's SIGTERM handler in the worker (ray/_private/worker.py, `main_loop.sigterm_handler`)
   raises `SystemExit(1)` at the next Python instruction: inside the runner's `__del__`,
   where Python cannot raise it and prints "Exception ignored in" with the traceback.

`install()` makes `clear()` end every actor before it forgets it: a force kill sent while
this process still holds the handles (so no graceful destroy can overtake it), then a wait
until Ray reports each actor dead and, for actors on this node, until the process has exited.
When Tune frees the placement group no runner is left to receive the SIGTERM. The wait is
bounded (`WAIT_S`); an actor that does not die in time is left to Ray, as before.

The trainable itself cannot be gone before its own `stop()` returns: Tune frees the placement
group right after, and its SIGTERM can land while the trainable runs a finalizer (seen once in
a soak: `(AsorPPO(...) pid=…) Exception ignored in: <function LearnerGroup.__del__>`). In a Ray
actor `install()` therefore also wraps Ray's SIGTERM handler: a SIGTERM that arrives inside a
`__del__` is delivered again 20 ms later instead of raising there (Ray's handler then runs as
before; the raylet's SIGKILL follows 200 ms after its SIGTERM in any case).
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from collections.abc import Iterable
from types import FrameType
from typing import Any

WAIT_S = 10.0
"""Longest `clear()` waits for its actors to die (normally a few milliseconds)."""
ASK_S = 2.0
"""Longest it waits for the actors' process ids (an actor busy or hung answers late: it is
then waited for through Ray only)."""
POLL_S = 0.01
RETRY_S = 0.02
"""How long a SIGTERM that arrived inside a finalizer waits before it is delivered again."""


def _process_ids(handles: list[Any], timeout_s: float) -> dict[int, int]:
    """index -> pid of the actors that run on this node and answer within `timeout_s`."""
    import ray

    def where(_actor: Any) -> tuple[int, str]:  # local: travels by value, no import there
        return os.getpid(), ray.get_runtime_context().get_node_id()

    refs = {}
    for i, h in enumerate(handles):
        try:
            refs[h.__ray_call__.remote(where)] = i
        except Exception:  # not an actor handle Ray can call: waited for through Ray only
            continue
    if not refs:
        return {}
    ready, _ = ray.wait(list(refs), num_returns=len(refs), timeout=timeout_s)
    here = ray.get_runtime_context().get_node_id()
    pids = {}
    for ref in ready:
        try:
            pid, node = ray.get(ref)
        except Exception:  # already dead, or failing: nothing to wait for here
            continue
        if node == here and pid != os.getpid():
            pids[refs[ref]] = pid
    return pids


def _process_gone(pid: int) -> bool:
    import psutil

    try:
        return psutil.Process(pid).status() == psutil.STATUS_ZOMBIE  # exited, not yet reaped
    except psutil.NoSuchProcess:
        return True
    except psutil.Error:  # no access: cannot tell, do not wait on it
        return True


def _dead(handle: Any, timeout_s: float) -> bool:
    """Whether Ray reports the actor dead (a call to it fails) within `timeout_s`."""
    import ray

    try:
        ray.get(handle.__ray_ready__.remote(), timeout=max(timeout_s, 0.0))
    except ray.exceptions.GetTimeoutError:
        return False
    except ray.exceptions.RayError:
        return True
    return False  # answered: the kill has not reached it yet


def kill_and_wait(handles: Iterable[Any], timeout_s: float = WAIT_S) -> list[Any]:
    """Force-kill the actors `handles` (no restart) and wait, up to `timeout_s` in all, until
    each is dead: its process gone where it runs on this node, else reported dead by Ray.
    The caller holds the handles meanwhile. Returns those not confirmed dead in time."""
    import ray

    handles = list(handles)
    if not handles:
        return []
    deadline = time.monotonic() + timeout_s
    pids = _process_ids(handles, min(ASK_S, timeout_s))
    for h in handles:
        try:
            ray.kill(h, no_restart=True)
        except Exception:  # already gone, or not an actor handle: nothing to kill
            continue
    waiting = list(range(len(handles)))
    while waiting:
        left = deadline - time.monotonic()
        still = []
        for i in waiting:
            if i in pids:
                done = _process_gone(pids[i])
            else:
                done = _dead(handles[i], min(max(left, 0.0), 0.5))
            if not done:
                still.append(i)
        waiting = still
        if not waiting or time.monotonic() >= deadline:
            break
        time.sleep(POLL_S)
    return [handles[i] for i in waiting]


def _in_finalizer(frame: FrameType | None) -> bool:
    while frame is not None:
        if frame.f_code.co_name == "__del__":
            return True
        frame = frame.f_back
    return False


def guard_sigterm() -> bool:
    """Wrap this process's SIGTERM handler (Ray's, in a Ray worker) so that a SIGTERM arriving
    inside a `__del__` is re-sent `RETRY_S` later instead of raising `SystemExit` there (Python
    can only print it: "Exception ignored in"); during interpreter shutdown it is dropped (the
    process is exiting). Idempotent; only from the main thread. Whether the handler is ours."""
    if threading.current_thread() is not threading.main_thread():
        return False
    current = signal.getsignal(signal.SIGTERM)
    if getattr(current, "defers_in_finalizers", False):
        return True
    if not callable(current):  # SIG_DFL / SIG_IGN: no Python handler raises anything
        return False

    def handler(signum: int, frame: FrameType | None) -> Any:
        if sys.is_finalizing():
            return None
        if _in_finalizer(frame):
            try:
                timer = threading.Timer(RETRY_S, os.kill, (os.getpid(), signum))
                timer.daemon = True
                timer.start()
            except RuntimeError:  # no new threads at shutdown: the SIGKILL that follows ends it
                pass
            return None
        return current(signum, frame)

    handler.defers_in_finalizers = True  # type: ignore[attr-defined]
    signal.signal(signal.SIGTERM, handler)
    return True


def _in_ray_actor() -> bool:
    import ray

    if not ray.is_initialized():
        return False
    try:
        return ray.get_runtime_context().get_actor_id() is not None
    except Exception:
        return False


def install() -> None:
    """Make every `FaultTolerantActorManager.clear()` (RLlib's env runner, evaluation and
    aggregator actor managers) kill its actors and wait for them before forgetting them, and
    in a Ray actor (a trainable, an env runner) guard the SIGTERM handler (`guard_sigterm`).
    Idempotent; runs in every process that imports our callbacks, i.e. every trainable the CLI
    or `with_asor` builds."""
    from ray.rllib.utils.actor_manager import FaultTolerantActorManager

    if _in_ray_actor():
        guard_sigterm()

    original = FaultTolerantActorManager.clear
    if getattr(original, "waits_for_actors", False):
        return

    def clear(self: Any) -> None:
        kill_and_wait(self.actors().values())
        original(self)  # kills again (a no-op on dead actors) and forgets them

    clear.waits_for_actors = True  # type: ignore[attr-defined]
    clear.__doc__ = original.__doc__
    FaultTolerantActorManager.clear = clear  # type: ignore[method-assign]
