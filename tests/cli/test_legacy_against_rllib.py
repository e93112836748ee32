"""Each old key our legacy table translates, checked against what RLlib 2.60 itself says the
old name became, not against our own table: its deprecation messages (`deprecation_warning(old=,
new=|help=)` anywhere in `ray.rllib`, per algorithm where an algorithm's file says otherwise),
`AlgorithmConfig._translate_special_keys`, the old-stack code that falls back from the new name
to the old one, and the 2.60 setter signatures (the new name is a parameter of a setter). A wrong
entry in the table fails here."""

from __future__ import annotations

import ast
import functools
import inspect
import re
from pathlib import Path

import pytest
import ray.rllib
from ray.rllib.algorithms.algorithm_config import AlgorithmConfig
from ray.rllib.algorithms.cql import CQLConfig
from ray.rllib.algorithms.dqn import DQNConfig
from ray.rllib.algorithms.ppo import PPOConfig
from ray.rllib.algorithms.sac import SACConfig
from ray.rllib.utils.from_config import NotProvided

from rllib_asor.cli import legacy

RLLIB = Path(ray.rllib.__file__).parent
WORD = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def _text(node: ast.AST) -> str:
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return node.value
    if isinstance(node, ast.JoinedStr):
        return "".join(_text(v) for v in node.values)
    if isinstance(node, ast.BinOp):
        return _text(node.left) + _text(node.right)
    return ""


@functools.lru_cache(maxsize=1)
def deprecations() -> list[tuple[str, str, str]]:
    """(old text, new-or-help text, file) of every `deprecation_warning` call in ray.rllib."""
    out = []
    for path in RLLIB.rglob("*.py"):
        if {"tests", "examples"} & set(path.parts):
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            func = getattr(node, "func", None)
            name = getattr(func, "id", getattr(func, "attr", None))
            if isinstance(node, ast.Call) and name == "deprecation_warning":
                kw = {k.arg: _text(k.value) for k in node.keywords}
                new = " ".join(filter(None, (kw.get("new"), kw.get("help"))))
                if kw.get("old") and new:
                    out.append((kw["old"], new, str(path.relative_to(RLLIB))))
    return out


@functools.lru_cache(maxsize=1)
def fallbacks() -> set[tuple[str, str]]:
    """(new, old) where old-stack code reads `config.get(new)` and, if None, `config.get(old)`."""
    pattern = re.compile(
        r'config\.get\("(?P<new>\w+)"\)\s*\n\s*if (?P<var>\w+) is None:\s*\n\s*(?P=var) = '
        r'self\.config\.get\(\s*"(?P<old>\w+)"'
    )
    pairs = set()
    for path in (RLLIB / "policy").glob("*.py"):
        for m in pattern.finditer(path.read_text(encoding="utf-8")):
            pairs.add((m["new"], m["old"]))
    return pairs


def rllib_says(old: str, run: str | None = None) -> set[str]:
    """Every name RLlib says `old` became (for `run`'s own files, only what they say when
    they say anything)."""
    own, common = set(), set()
    for old_text, new_text, file in deprecations():
        if old in WORD.findall(old_text):
            names = set(WORD.findall(new_text))
            parts = file.split("/")
            folder = parts[1] if len(parts) > 2 and parts[0] == "algorithms" else ""
            if run is not None and folder == run.lower():
                own |= names
            else:
                common |= names
    translated = AlgorithmConfig._translate_special_keys(old, warn_deprecated=False)
    if translated != old:
        common.add(translated)
    common |= {new for new, fallback_old in fallbacks() if fallback_old == old}
    return own or common


@functools.lru_cache(maxsize=1)
def setter_parameters() -> set[str]:
    """The parameters (default NotProvided) of every public setter of 2.60's configs."""
    names = set()
    for cls in (AlgorithmConfig, PPOConfig, SACConfig, DQNConfig, CQLConfig):
        for name, fn in vars(cls).items():
            if not name.startswith("_") and inspect.isfunction(fn):
                for p in inspect.signature(fn).parameters.values():
                    if p.default is NotProvided:
                        names.add(p.name)
    return names


@pytest.mark.parametrize("old, new", sorted(legacy.RENAMED_CONFIG_KEYS.items()))
def test_rllib_says_the_old_key_became_ours(old, new):
    said = rllib_says(old)
    assert said, f"RLlib 2.60 says nothing about {old!r}: no evidence for {old} -> {new}"
    assert new in said, f"{old} -> {new}, but RLlib says {old} became one of {sorted(said)}"
    assert new in setter_parameters(), f"{new} is no setter parameter of RLlib 2.60"


@pytest.mark.parametrize(
    "run, old, new",
    sorted((run, old, new) for run, t in legacy.RENAMED_CONFIG_KEYS_BY_RUN.items()
           for old, new in t.items()),  # fmt: skip
)
def test_an_algorithms_own_deprecation_message_wins(run, old, new):
    assert new in rllib_says(old, run) and new in setter_parameters()
    out, _ = legacy.translate_config({old: 5}, "f.yaml", run=run)
    assert out == {new: 5}


@pytest.mark.parametrize("run", ["CQL", "SAC", "PPO", "DQN"])
def test_every_table_translation_agrees_with_the_algorithms_own_files(run):
    """Where an algorithm's own file names a different new key than the common one, the
    translation for that run follows the algorithm's file."""
    for old in {*legacy.RENAMED_CONFIG_KEYS, *legacy.RENAMED_CONFIG_KEYS_BY_RUN.get(run, {})}:
        out, _ = legacy.translate_config({old: 5}, "f.yaml", run=run)
        (new,) = out
        assert new in rllib_says(old, run), (run, old, new, rllib_says(old, run))


@pytest.mark.parametrize(
    "old, wrong",
    [("min_iter_time_s", "min_train_timesteps_per_iteration"),
     ("evaluation_num_workers", "num_env_runners"),
     ("sgd_minibatch_size", "train_batch_size"),
     ("num_cpus_for_driver", "num_cpus_per_learner")],
)  # fmt: skip
def test_a_wrong_entry_fails(monkeypatch, old, wrong):
    """The check is not the table reading itself: a plausible but wrong target fails it."""
    monkeypatch.setitem(legacy.RENAMED_CONFIG_KEYS, old, wrong)
    with pytest.raises(AssertionError):
        test_rllib_says_the_old_key_became_ours(old, legacy.RENAMED_CONFIG_KEYS[old])
    monkeypatch.setitem(legacy.RENAMED_CONFIG_KEYS, "no_such_old_key", "lr")
    with pytest.raises(AssertionError, match="says nothing"):
        test_rllib_says_the_old_key_became_ours("no_such_old_key", "lr")


@functools.lru_cache(maxsize=1)
def tune_run_says() -> dict[str, set[str]]:
    """Old `tune.run` argument -> what Tune 2.60's own translation sets: the
    `checkpoint_config.<attr> = ...` assignments under `if <old> ...:`, and the names its
    deprecation text for the argument points to."""
    import ray.tune.tune as tune_module

    tree = ast.parse(Path(tune_module.__file__).read_text(encoding="utf-8"))
    run = next(n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef) and n.name == "run")
    said: dict[str, set[str]] = {}
    for node in ast.walk(run):
        if not isinstance(node, ast.If):
            continue
        olds = {n.id for n in ast.walk(node.test) if isinstance(n, ast.Name)}
        for inner in ast.walk(node):
            targets = getattr(inner, "targets", [])
            for t in targets:
                if isinstance(t, ast.Attribute) and getattr(t.value, "id", "") == "checkpoint_config":
                    for old in olds:
                        said.setdefault(old, set()).add(t.attr)
            if isinstance(inner, ast.Constant) and isinstance(inner.value, str):
                for old in olds:
                    said.setdefault(old, set()).update(WORD.findall(inner.value))
    return said


@pytest.mark.parametrize("old, target", sorted(legacy.RENAMED_SPEC_KEYS.items()))
def test_experiment_keys_go_where_tune_run_sent_them(old, target):
    _, new = target
    assert new in tune_run_says().get(old, set()), (old, new, tune_run_says().get(old))


def test_checkpoint_score_attr_keeps_tunes_min_prefix_and_new_result_names():
    from rllib_asor.cli.spec import parse_experiment

    spec = {"run": "PPO", "env": "CartPole-v1", "checkpoint_score_attr": "min-episode_reward_mean"}
    exp = parse_experiment("e", spec, "f.yaml")
    assert exp.checkpoint_config == {
        "checkpoint_score_attribute": "env_runners/episode_return_mean",
        "checkpoint_score_order": "min",
    }
    assert {"checkpoint_score_attribute", "checkpoint_score_order"} <= tune_run_says()[
        "checkpoint_score_attr"
    ]


def test_sac_optimization_keys_become_sac_setter_parameters():
    """`optimization: {actor_learning_rate, ...}` (old SAC) lands on 2.60 `SACConfig.training`
    parameters, and `entropy_learning_rate` on the one for the entropy coefficient alpha."""
    from rllib_asor.cli import retired

    params = inspect.signature(SACConfig.training).parameters
    assert set(retired.OPTIMIZATION_KEYS.values()) <= set(params)
    assert set(retired.OPTIMIZATION_KEYS) == set(SACConfig().optimization)  # RLlib's old dict
    for old, new in retired.OPTIMIZATION_KEYS.items():
        assert old.split("_")[0] in {"actor": "actor", "critic": "critic", "alpha": "entropy"}[
            new.split("_")[0]
        ], (old, new)


def test_replay_keys_land_where_rllib_reads_them():
    """`buffer_size` -> `capacity` is RLlib's own deprecation message; every replay key we
    write is a constructor argument of the new-stack buffer or a key of SAC's default
    replay_buffer_config; a prioritized old type stays prioritized."""
    from ray.rllib.utils import replay_buffers

    from rllib_asor.cli import retired

    assert "capacity" in rllib_says("buffer_size")
    known = set(SACConfig().replay_buffer_config)
    for cls in (replay_buffers.PrioritizedEpisodeReplayBuffer, replay_buffers.EpisodeReplayBuffer):
        known |= set(inspect.signature(cls.__init__).parameters)
    assert set(retired.REPLAY_TOP_KEYS.values()) <= known
    for old, new in retired.REPLAY_TYPES.items():
        new_cls = getattr(replay_buffers, new)
        assert issubclass(new_cls, replay_buffers.EpisodeReplayBuffer)
        assert ("Prioritized" in old) == ("Prioritized" in new), (old, new)
