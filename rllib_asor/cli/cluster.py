"""Starting a local Ray, or joining a cluster after checking that its address answers."""

from __future__ import annotations

import math
import os
import socket
from typing import TYPE_CHECKING, Any

from rllib_asor.cli.errors import UsageError

if TYPE_CHECKING:
    from rllib_asor.cli.spec import Experiment

PROBE_TIMEOUT_S = 3.0
DEFAULT_GCS_PORT = 6379
DEFAULT_CLIENT_PORT = 10001


def parse_address(address: str) -> tuple[str, int] | None:
    """(host, port) to probe for an address; None for 'auto'/'local' (Ray resolves those)."""
    if address in ("auto", "local"):
        return None
    rest = address
    default_port = DEFAULT_GCS_PORT
    if "://" in rest:
        scheme, rest = rest.split("://", 1)
        if scheme == "ray":
            default_port = DEFAULT_CLIENT_PORT
    host, sep, port = rest.rpartition(":")
    if not sep:
        host, port = rest, str(default_port)
    host = host.strip("[]")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise UsageError(
            f"{address!r} is invalid: allowed HOST:PORT (e.g. 10.0.0.1:6379), ray://HOST:PORT or auto",
            key="--address",
        )
    return host, int(port)


def probe(address: str, timeout: float = PROBE_TIMEOUT_S) -> None:
    """Raise UsageError within `timeout` seconds if nothing listens at `address`."""
    target = parse_address(address)
    if target is None:
        return
    try:
        with socket.create_connection(target, timeout=timeout):
            pass
    except OSError as e:
        reason = e.strerror or type(e).__name__
        if isinstance(e, TimeoutError | socket.timeout):
            reason = f"no answer within {timeout:g} s"
        raise UsageError(
            f"cannot reach a Ray cluster at {address} ({reason}); start one with "
            "'ray start --head' or give the head node's HOST:PORT",
            key="--address",
        ) from None


def start_ray(address: str | None, cpus_needed: float) -> bool:
    """Join `address`, or start a local Ray with enough logical CPUs for one trial; whether
    this call connected (False: Ray was already initialised)."""
    import ray

    from rllib_asor.cli import quiet

    if ray.is_initialized():
        return False
    quiet.quiet_driver()
    os.environ.setdefault("RAY_memory_monitor_refresh_ms", "0")
    os.environ.setdefault("RAY_DISABLE_DOCKER_CPU_WARNING", "1")
    if address:
        probe(address)
        try:
            ray.init(address=address, include_dashboard=False, log_to_driver=True)
        except (ConnectionError, RuntimeError, ValueError) as e:
            msg = " ".join(str(e).split())[:200]
            raise UsageError(
                f"cannot join the Ray cluster at {address}: {msg}", key="--address"
            ) from None
    else:
        num_cpus = max(os.cpu_count() or 1, math.ceil(cpus_needed))
        ray.init(address="local", num_cpus=num_cpus, include_dashboard=False)
    quiet.quiet_driver()  # again: ray.init may add handlers
    quiet.quiet_worker_lines()
    return True


def check_local_gpus(exp: Experiment, algo_config: Any) -> None:
    """UsageError when a trial asks for GPUs and torch sees none on this machine: a local Ray
    would keep the trial waiting for them forever."""
    from rllib_asor.cli.build import required_gpus
    from rllib_asor.cli.overrides import cuda_available

    needed = required_gpus(algo_config)
    if needed > 0 and not cuda_available():
        asked = ", ".join(
            f"{key}: {exp.config[key]}"
            for key in ("num_gpus_per_learner", "num_gpus_per_env_runner", "num_gpus")
            if exp.config.get(key)
        )
        raise UsageError(
            f"a trial asks for {needed:g} GPU(s) ({asked or 'the config'}) and torch sees no "
            "CUDA device here, so Ray would wait for them forever; allowed on this machine: "
            "num_gpus_per_learner: 0 (the Learner on the CPU), --test (which sets them to 0), "
            "or --address of a Ray cluster with GPUs",
            source=exp.source,
            key=f"{exp.name}.config",
        )
