"""Every way people name an env, resolved to something every process can build.

`resolve_env(name)` accepts, in this order:
- an id known here: ours, the race's, gymnasium's, one registered with Tune;
- gymnasium's `module:EnvId` (the module registers the id when imported);
- a class or creator function as `package.module:Name` or `package.module.Name` (RLlib's own
  example envs also under their old module paths, `ray.rllib.examples.env.*`);
- an old version of a gymnasium id (`Pendulum-v0`, `Hopper-v1`, `HalfCheetah-v3`) → the newest
  version that runs here;
- an id the calling script registered with `gym.register` (its spec travels to the workers).

Modules resolve as Python resolves them from where the user runs: the current folder is
importable (as with `python -m`), then `PYTHONPATH`. No module is imported unless the name
names it: an id that only a module of the user's registers must be given as `module:EnvId`
(the unknown-id message says so, naming the module whose text mentions the id).

`build_env(ref, env_config)` makes the env in any process (driver or env runner): it imports the
module first, so a Tune creator holding the `EnvRef` works on every node that can import it.
A name that cannot be resolved raises `ValueError` with one line: what is wrong, and what to do.
"""

from __future__ import annotations

import difflib
import functools
import importlib
import inspect
import os
import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rllib_asor import ray_compat as compat
from rllib_asor.registry import envs

# Old module path prefix -> where RLlib moved it (Ray 2.10: examples/env -> examples/envs/classes).
MOVED_ENV_MODULES = {"ray.rllib.examples.env.": "ray.rllib.examples.envs.classes."}
_VERSIONED = re.compile(r"^(?P<base>.+)-v(?P<version>\d+)$")
_SCAN_LIMIT = 500  # .py files read (never imported) per folder for the unknown-id hint


@dataclass(frozen=True)
class EnvRef:
    """How to build an env a user named: import `module`, then make `env_id` (gymnasium), call
    `attr` (a class or creator in `module`), or make `spec` (registered by the driver only)."""

    name: str
    env_id: str | None = None
    module: str | None = None
    attr: str | None = None
    spec: Any = None
    note: str | None = None
    """What was translated, for a warning (e.g. an old gym id), else None."""
    tune: bool = False
    """Built by a creator someone registered with Tune under `name`."""


_REGISTERED: dict[str, EnvRef] = {}
"""Names `register_env` registered with Tune in this process, and what they resolved to."""


def resolve_env(name: str) -> EnvRef:
    """The `EnvRef` for `name` (see the module docstring); ValueError if there is none."""
    import gymnasium as gym

    if not isinstance(name, str) or not name:
        raise ValueError(f"env {name!r} is invalid: allowed an env id or 'package.module:Class'")
    if name in _REGISTERED:
        return _REGISTERED[name]
    importable_cwd()
    if envs.env_exists(name):
        if name not in gym.registry and name not in envs.race_creators():
            return EnvRef(name, tune=True)  # someone else's Tune creator
        return _known(name, gym.registry.get(name))
    if ":" in name:
        module, _, attr = name.partition(":")
        return _from_module(name, module, attr)
    newer = newer_version(name)
    if newer is not None:
        return EnvRef(name, env_id=newer, note=f"env id '{name}' translated to '{newer}'")
    if "." in name and not _VERSIONED.match(name):
        module, _, attr = name.rpartition(".")
        return _from_module(name, module, attr)
    raise ValueError(_unknown_id(name))


def importable_cwd() -> None:
    """Make the current folder importable, as `python -m` does (first on `sys.path`); an
    env's module or entry point next to the user's YAML file then imports. Imports nothing."""
    cwd = os.getcwd()
    if cwd not in sys.path:
        sys.path.insert(0, cwd)


def _known(name: str, spec: Any) -> EnvRef:
    """A registered id; a spec registered by the calling script (not importable elsewhere)
    travels with the ref."""
    if (
        spec is None
        or isinstance(spec.entry_point, str)
        and spec.entry_point.startswith(
            ("gymnasium.", "rllib_asor.", "game_env.", "highway_env.", "ale_py", "shimmy")
        )
    ):
        return EnvRef(name, env_id=name)
    if _raises_on_make(spec):
        newer = newer_version(name)
        if newer is not None:
            return EnvRef(name, env_id=newer, note=f"env id '{name}' translated to '{newer}'")
    return EnvRef(name, env_id=name, spec=spec)


def _raises_on_make(spec: Any) -> bool:
    """gymnasium keeps MuJoCo v2/v3 ids whose entry point only raises (they need mujoco-py)."""
    return getattr(spec.entry_point, "__name__", "").startswith("_raise")


def newer_version(name: str) -> str | None:
    """The newest runnable registered version of an older or unrunnable `Name-vN`, else None."""
    import gymnasium as gym

    match = _VERSIONED.match(name)
    if match is None:
        return None
    base, version = match["base"], int(match["version"])
    runnable = [
        int(m["version"])
        for key, spec in gym.registry.items()
        if (m := _VERSIONED.match(key)) and m["base"] == base and not _raises_on_make(spec)
    ]
    if not runnable or max(runnable) <= version and f"{base}-v{version}" not in gym.registry:
        return None
    newest = max(runnable)
    return f"{base}-v{newest}" if newest != version else None


def _from_module(name: str, module: str, attr: str) -> EnvRef:
    """`module:attr` / `module.attr`: a gymnasium id the module registers, or a class/creator."""
    import gymnasium as gym

    imported = _import(name, module)
    if attr in gym.registry:
        return EnvRef(name, env_id=attr, module=imported)
    obj = getattr(sys.modules[imported], attr, None)
    if obj is None or not callable(obj):
        raise ValueError(
            f"env {name!r}: module {imported!r} has no env class, creator function or registered "
            f"gymnasium id {attr!r}"
        )
    return EnvRef(name, module=imported, attr=attr)


def _import(name: str, module: str) -> str:
    """Import `module` (or its moved RLlib path); the name that imported, or ValueError."""
    candidates = [module] + [
        new + module[len(old) :] for old, new in MOVED_ENV_MODULES.items() if module.startswith(old)
    ]
    error: BaseException | None = None
    for candidate in candidates:
        try:
            importlib.import_module(candidate)
            return candidate
        except ImportError as e:
            error = error or e
        except Exception as e:  # the module itself fails: say so, in one line
            raise ValueError(
                f"env {name!r}: importing module {candidate!r} failed: "
                f"{type(e).__name__}: {' '.join(str(e).split())}"
            ) from None
    path = os.environ.get("PYTHONPATH", "")
    raise ValueError(
        f"env {name!r}: module {module!r} cannot be imported ({error}); looked in the current "
        f"folder {os.getcwd()!r} and on PYTHONPATH (now {path!r}): run from the module's folder "
        "or put that folder on PYTHONPATH"
    )


def _mentioning_modules(env_id: str) -> list[str]:
    """Top-level modules in the current folder or on PYTHONPATH whose text names `env_id`
    (read, never imported): the hint of the unknown-id message."""
    folders = [os.getcwd(), *filter(None, os.environ.get("PYTHONPATH", "").split(os.pathsep))]
    quoted = (f'"{env_id}"', f"'{env_id}'")
    found: list[str] = []
    for folder in dict.fromkeys(folders):
        for path in sorted(Path(folder).glob("*.py"))[:_SCAN_LIMIT]:
            try:
                text = path.read_text(encoding="utf-8", errors="ignore")
            except OSError:
                continue
            if any(q in text for q in quoted) and path.stem not in found:
                found.append(path.stem)
    return found


def _unknown_id(name: str) -> str:
    """One line: the close ids, how to name a module of one's own (with this id), and where
    modules are looked for."""
    import gymnasium as gym

    ids = [*gym.registry, *envs.race_creators()]
    close = difflib.get_close_matches(name, ids, n=3, cutoff=0.6)
    hint = f"close ids: {', '.join(close)}; " if close else ""
    mentioning = _mentioning_modules(name)
    module = mentioning[0] if mentioning else "mymodule"
    named = (
        f"did you mean '{module}:{name}'? ({module}.py names this id; a module is imported only "
        "when the name names it); "
        if mentioning
        else ""
    )
    return (
        f"unknown env id {name!r}; {named}{hint}allowed: a registered id ({envs.known_ids()}), "
        f"or a name that names its module: '{module}:{name}' (the module registers the id), "
        f"'{module}:MyEnv' or '{module}.MyEnv' (an env class or creator); modules are found "
        "in the current folder and on PYTHONPATH"
    )


def build_env(ref: EnvRef, env_config: Any = None) -> Any:
    """The env `ref` names, made in this process (imports its module first)."""
    import gymnasium as gym

    config = dict(env_config or {})
    if ref.tune:
        from ray.tune.registry import ENV_CREATOR

        return compat.tune_registry_get(ENV_CREATOR, ref.name)(
            env_config if env_config is not None else config
        )
    if ref.module is not None:
        importlib.import_module(ref.module)
    if ref.attr is not None:
        return _call(getattr(sys.modules[ref.module], ref.attr), env_config, config)
    if ref.spec is not None:
        return gym.make(ref.spec, **config)
    return envs.make_env(ref.env_id, config)


def _call(factory: Any, env_config: Any, config: dict[str, Any]) -> Any:
    """RLlib's convention (one `env_config` argument) when the class/function takes one
    positional argument; gymnasium's (keyword arguments) otherwise."""
    try:
        params = list(inspect.signature(factory).parameters.values())
    except (TypeError, ValueError):
        return factory(env_config if env_config is not None else config)
    positional = [p for p in params if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
    takes_config = positional and (
        positional[0].default is inspect.Parameter.empty
        or positional[0].name in ("config", "env_config", "env_context")
    )
    if takes_config:
        return factory(env_config if env_config is not None else config)
    return factory(**config)


def register_env(name: str) -> EnvRef:
    """Resolve `name` and register a Tune creator for it under that name, so env runners on
    every node build it (a creator someone else registered is kept). ValueError if unknown."""
    from ray import tune

    ref = resolve_env(name)
    if not ref.tune and not envs.in_tune_registry(name):
        tune.register_env(name, functools.partial(build_env, ref))
        _REGISTERED[name] = ref
    return ref
