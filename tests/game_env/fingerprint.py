"""A fingerprint of the race's behaviour: fixed scenarios hashed step by step.

Each scenario drives an env (single racer or PettingZoo) with a fixed action stream (random
or the scripted racer) and hashes everything the env returns: observations (bytes), rewards,
terminations, truncations and infos (reward terms, episode metrics, ids), plus the messages of
rejected arguments. ``tests/game_env/test_fingerprint.py`` compares against
``fingerprint.json``, recorded from the code before a refactor, so that a refactor that
changes any number fails.

    python -m tests.game_env.fingerprint            # print the current hashes
    python -m tests.game_env.fingerprint --write    # re-record (only for an intended change)
"""

from __future__ import annotations

import argparse
import hashlib
import json
import struct
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

FIXTURE = Path(__file__).with_name("fingerprint.json")


def _feed(h: Any, x: Any) -> None:
    """Hash ``x`` canonically: types, order and every bit of every number count."""
    if isinstance(x, np.ndarray):
        h.update(f"A{x.dtype.str}{x.shape}".encode())
        h.update(np.ascontiguousarray(x).tobytes())
    elif isinstance(x, dict):
        h.update(b"D%d" % len(x))
        for k, v in x.items():
            _feed(h, k)
            _feed(h, v)
    elif isinstance(x, (list, tuple)):
        h.update(b"L%d" % len(x))
        for v in x:
            _feed(h, v)
    elif isinstance(x, str):
        h.update(b"S" + x.encode() + b"\0")
    elif isinstance(x, (float, np.floating)):
        h.update(type(x).__name__.encode() + struct.pack("<d", float(x)))
    elif isinstance(x, (bool, int, np.integer, np.bool_)):
        h.update(type(x).__name__.encode() + str(int(x)).encode() + b"\0")
    elif x is None:
        h.update(b"N")
    else:
        raise TypeError(f"cannot fingerprint {type(x).__name__}")


class _Digest:
    def __init__(self) -> None:
        self.h = hashlib.sha256()
        self.steps = 0
        self.reward = 0.0
        self.terms: dict[str, float] = {}

    def add(self, *items: Any) -> None:
        for x in items:
            _feed(self.h, x)

    def note(self, reward: float, info: dict[str, Any]) -> None:
        self.steps += 1
        self.reward += float(reward)
        for k, v in info.get("reward_terms", {}).items():
            self.terms[k] = self.terms.get(k, 0.0) + v

    def result(self) -> dict[str, Any]:
        return {"sha256": self.h.hexdigest(), "steps": self.steps, "reward": round(self.reward, 9),
                "terms": {k: round(v, 9) for k, v in self.terms.items()}}


def _shape(act: np.ndarray, policy: str) -> np.ndarray:
    """Random actions, or (``forward``) random ones that always run +x: they fall into gaps;
    ``forward-walk`` never jumps either: it presses into walls."""
    if policy.startswith("forward"):
        act[0], act[1], act[7] = 2, 1, 0
        if policy == "forward-walk":
            act[2] = 0
    return act


def _single(map_id: Any, course_seed: Any, seed: int, steps: int, policy: str, max_steps: int = 1000,
            frame_skip: int | None = None) -> dict[str, Any]:
    from game_env.env import ObstacleRaceEnv
    from game_env.scripted import ScriptedRacer

    kwargs = {} if frame_skip is None else {"frame_skip": frame_skip}
    env = ObstacleRaceEnv(map_id=map_id, course_seed=course_seed, max_episode_steps=max_steps, **kwargs)
    d = _Digest()
    obs, info = env.reset(seed=seed)
    d.add(obs, info)
    rng = np.random.default_rng(seed)
    scripted = ScriptedRacer(env) if policy == "scripted" else None
    for _ in range(steps):
        act = scripted.act() if scripted is not None else _shape(rng.integers(0, env.action_space.nvec), policy)
        obs, reward, term, trunc, info = env.step(act)
        d.add(obs, reward, term, trunc, info)
        d.note(reward, info)
        if term or trunc:
            obs, info = env.reset()
            d.add("reset", obs, info)
            if scripted is not None:
                scripted = ScriptedRacer(env)
    env.close()
    return d.result()


def _multi(num_racers: int, map_id: Any, seed: int, steps: int, scripted: int = 0,
           max_steps: int = 1000, policy: str = "random") -> dict[str, Any]:
    import game_env
    from game_env.scripted import ScriptedRacer

    env = game_env.parallel_env(num_racers=num_racers, map_id=map_id, max_episode_steps=max_steps)
    d = _Digest()
    obs, infos = env.reset(seed=seed)
    d.add(obs, infos)
    rng = np.random.default_rng(seed)
    bots = {f"racer_{i}": ScriptedRacer(env, f"racer_{i}") for i in range(scripted)}
    for _ in range(steps):
        acts = {}
        for a in env.possible_agents:  # one draw per racer and step, live or not: a fixed stream
            act = _shape(rng.integers(0, env.action_space(a).nvec), policy)
            act[4] = 1  # attack often
            if a in bots:
                act = bots[a].act()
            if a in env.agents:
                acts[a] = act
        obs, rew, term, trunc, infos = env.step(acts)
        d.add(obs, rew, term, trunc, infos, list(env.agents))
        for a in rew:
            d.note(rew[a], infos[a])
        if not env.agents:
            obs, infos = env.reset()
            d.add("reset", obs, infos)
            bots = {a: ScriptedRacer(env, a) for a in bots}
    env.close()
    return d.result()


def _blow_up(multi: bool) -> dict[str, Any]:
    """A physics blow-up mid-episode: the truncating step, its warning (where it points), and
    the episode after a reset."""
    import warnings

    import game_env
    from game_env.env import ObstacleRaceEnv

    d = _Digest()
    rng = np.random.default_rng(21)
    env = game_env.parallel_env(num_racers=2, map_id=1, course_seed=4) if multi else ObstacleRaceEnv(map_id=0)
    d.add(env.reset(seed=3))
    for k in range(60):
        if k == 20:
            if multi:
                env.data.qpos[1] = np.inf
            else:
                env.data.qvel[0] = np.nan
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            if multi:
                out = env.step({a: rng.integers(0, env.action_space(a).nvec) for a in env.agents})
            else:
                out = env.step(rng.integers(0, env.action_space.nvec))
        d.add(out, [(w.category.__name__, str(w.message), Path(w.filename).name) for w in caught])
        for reward, info in zip(*((out[1].values(), out[4].values()) if multi else ([out[1]], [out[4]])), strict=True):
            d.note(reward, info)
        if (not env.agents) if multi else (out[2] or out[3]):
            d.add("reset", env.reset())
    env.close()
    return d.result()


def _errors() -> dict[str, Any]:
    """The exception type and message of each rejected argument, for both envs."""
    import game_env
    from game_env.env import ObstacleRaceEnv

    bad_init: list[dict[str, Any]] = [
        {"map_id": 10}, {"map_id": -1}, {"map_id": "x"}, {"map_id": []}, {"map_id": [1, 99]},
        {"map_id": 1.5}, {"course_seed": -1}, {"course_seed": 1000}, {"course_seed": "a"},
        {"course_seed": True}, {"max_episode_steps": 0}, {"max_episode_steps": 2.0},
        {"frame_skip": 0}, {"frame_skip": 1001}, {"render_mode": "human"}, {"width": 8},
        {"height": 5000}, {"width": True},
    ]
    out: dict[str, Any] = {}

    def record(key: str, fn: Callable[[], Any]) -> None:
        try:
            fn()
        except Exception as e:  # noqa: BLE001 - the message is what is recorded
            out[key] = f"{type(e).__name__}: {e}"
        else:
            out[key] = "ok"

    for kw in bad_init:
        record(f"single {kw}", lambda kw=kw: ObstacleRaceEnv(**kw))
        record(f"multi {kw}", lambda kw=kw: game_env.parallel_env(num_racers=2, **kw))
    for n in (0, 17, 2.5):
        record(f"multi num_racers={n!r}", lambda n=n: game_env.parallel_env(num_racers=n))
    single = ObstacleRaceEnv(map_id=0, course_seed=0)
    multi = game_env.parallel_env(num_racers=2, map_id=0, course_seed=0)
    single.reset(seed=0)
    multi.reset(seed=0)
    for opts in ({"map_id": 12}, {"course_seed": -3}, {"foo": 1}, [1]):
        record(f"single reset {opts}", lambda o=opts: single.reset(options=o))
        record(f"multi reset {opts}", lambda o=opts: multi.reset(options=o))
    for act in ([3, 1, 0, 0, 0, 0, 0, 0], [1, 1, 0], "x", [1, 1, 0, 0, 0, 0, 8, 0]):
        record(f"single step {act!r}", lambda a=act: single.step(a))
        record(f"multi step {act!r}", lambda a=act: multi.step({"racer_0": a}))
    record("multi step unknown agent", lambda: multi.step({"racer_9": [1, 1, 0, 0, 0, 0, 0, 0]}))
    record("set_map_choice bad", lambda: single.set_map_choice(42))
    return out


SCENARIOS: dict[str, Callable[[], dict[str, Any]]] = {
    "single map0 random": lambda: _single(0, 3, 1, 300, "random"),
    "single map5 random": lambda: _single(5, 11, 2, 300, "random"),
    "single map9 random": lambda: _single(9, None, 3, 300, "random"),
    "single any-map random, short episodes": lambda: _single(None, None, 4, 300, "random", max_steps=70),
    "single maps[2,6] random, frame_skip 5": lambda: _single([2, 6], None, 5, 300, "random", frame_skip=5),
    "single map0 scripted": lambda: _single(0, 0, 6, 600, "scripted"),
    "single map4 scripted": lambda: _single(4, 2, 7, 600, "scripted"),
    "single map8 scripted": lambda: _single(8, 1, 8, 600, "scripted"),
    "single map1 forward": lambda: _single(1, 5, 12, 300, "forward"),
    "single map6 forward": lambda: _single(6, 8, 13, 300, "forward"),
    "single map2 forward-walk": lambda: _single(2, 4, 14, 300, "forward-walk"),
    "multi 4 map7 random": lambda: _multi(4, 7, 9, 300),
    "multi 3 map3 scripted+forward": lambda: _multi(3, 3, 10, 700, scripted=2, policy="forward"),
    "multi 2 any-map random, short": lambda: _multi(2, None, 11, 300, max_steps=90),
    "single physics blow-up": lambda: _blow_up(False),
    "multi physics blow-up": lambda: _blow_up(True),
}


def fingerprint() -> dict[str, Any]:
    """Every scenario's digest and the argument-error messages."""
    out: dict[str, Any] = {name: run() for name, run in SCENARIOS.items()}
    errs = _errors()
    out["argument errors"] = {"sha256": hashlib.sha256(json.dumps(errs).encode()).hexdigest(), "messages": errs}
    return out


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help=f"write {FIXTURE.name}")
    args = parser.parse_args(argv)
    fp = fingerprint()
    text = json.dumps(fp, indent=1) + "\n"
    if args.write:
        FIXTURE.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
