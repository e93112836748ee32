"""The wall around RLlib: every private Ray name we rely on exists in the installed Ray, and no
module but `rllib_asor/ray_compat.py` touches one."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import ray

from rllib_asor import ray_compat as compat

PACKAGE = Path(__file__).resolve().parents[2] / "rllib_asor"
COMPAT = PACKAGE / "ray_compat.py"

# Private RLlib names our package used directly before compat existed (and public stand-ins
# replaced some of them: Learner.module, Learner.device, MultiRLModule.items(),
# AlgorithmConfig.rl_module(model_config=...), Learner.filter_param_dict_for_optimizer).
# Learner._module (now `.module`) is not listed: MAPLE's Algorithm has a method of that name.
USED_BEFORE = {
    "_learner_class", "_rl_module_spec", "_env_to_module_connector", "_model_config",
    "_translate_special_keys", "_learner_connector", "_temp_losses", "_weights_seq_no",
    "_batch", "_num_covered_epochs", "_get_backend_config", "_learner", "_check_component",
    "_encoder_config", "_squash", "_global_registry", "_rl_modules", "_params",
    "_optimizer_parameters", "_get_tensor_variable", "_device", "_lock",
    "global_worker_stdstream_dispatcher", "DEPRECATED_VALUE",
}  # fmt: skip


def _private_names() -> set[str]:
    return USED_BEFORE | {p.name for p in compat.PRIVATE_NAMES}


def _is_self_or_super(node: ast.AST) -> bool:
    if isinstance(node, ast.Name):
        return node.id == "self"
    return (
        isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "super"
    )


def violations(path: Path, private: set[str], overrides: set[str], root: Path) -> list[str]:
    """`file:line name` for each access to a private Ray name in `path` (relative to `root`):
    an attribute, an import, or a string (getattr); an overridden private method only on
    `self`/`super()` (a subclass calling its own hook)."""
    out = []
    where = path.relative_to(root)
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        name = None
        if isinstance(node, ast.Attribute):
            if node.attr in private or (
                node.attr in overrides and not _is_self_or_super(node.value)
            ):
                name = node.attr
        elif isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "ray":
            parts = node.module.split(".") + [a.name for a in node.names]
            hidden = [p for p in parts if p.startswith("_") or p in private]
            name = ",".join(hidden) or None
        elif isinstance(node, ast.Import):
            hidden = [a.name for a in node.names if a.name.startswith("ray.") and "._" in a.name]
            name = ",".join(hidden) or None
        elif isinstance(node, ast.Constant) and isinstance(node.value, str):
            name = node.value if node.value in private else None
        if name:
            out.append(f"{where}:{node.lineno} {name}")
    return out


def unlisted_overrides(source: str, rllib_private: set[str]) -> list[str]:
    """`line name` of each method a class in `source` defines that is one of `rllib_private`
    and not in compat.OVERRIDES."""
    listed = {p.name for p in compat.OVERRIDES}
    return [
        f"{fn.lineno} {fn.name}"
        for cls in ast.walk(ast.parse(source))
        if isinstance(cls, ast.ClassDef)
        for fn in cls.body
        if isinstance(fn, ast.FunctionDef) and fn.name in rllib_private - listed
    ]


def test_every_private_name_compat_relies_on_exists_in_the_installed_ray():
    gone = compat.missing()
    assert not gone, (
        f"Ray {ray.__version__} lacks {', '.join(gone)} (rllib_asor/ray_compat.py is "
        f"tested with Ray {', '.join(compat.RAY_TESTED)})"
    )


def test_the_installed_ray_is_a_tested_release():
    """`make test` runs on the release pip picks from the range, `make compat` on each other."""
    assert compat.unsupported_ray(ray.__version__) is None, compat.unsupported_ray(
        ray.__version__
    )


def test_an_untested_ray_is_named_in_one_line_with_the_tested_ones():
    assert compat.unsupported_ray(compat.RAY_TESTED[-1]) is None
    said = compat.unsupported_ray("2.57.0")
    assert said is not None and "\n" not in said and said.startswith("Ray 2.57.0 ")
    assert all(v in said for v in compat.RAY_TESTED) and compat.RAY_REQUIREMENT in said


def test_a_name_gone_from_ray_is_reported(monkeypatch):
    gone = compat.Private("ray.rllib.core.learner.learner:Learner", "_gone_in_a_new_ray", "x")
    monkeypatch.setattr(compat, "PRIVATE_NAMES", (*compat.PRIVATE_NAMES, gone))
    monkeypatch.setattr(compat, "TO_DICT_KEYS", {**compat.TO_DICT_KEYS, "x": "_no_such_key"})
    assert compat.missing() == [
        "ray.rllib.core.learner.learner:Learner._gone_in_a_new_ray",
        "AlgorithmConfig.to_dict()['_no_such_key']",
    ]


def test_the_existence_check_can_fail():
    learner = "ray.rllib.core.learner.learner:Learner"
    assert compat._has(learner, "_weights_seq_no")  # an instance attribute, found in source
    assert compat._has(learner, "_update")  # a method
    assert not compat._has(learner, "_no_such_name")
    assert not compat._has("ray.tune.registry", "_no_such_name")
    assert not compat._has("ray.no_such_module:Class", "_x")


def test_no_module_but_compat_touches_a_private_ray_name():
    private = _private_names()
    overrides = {p.name for p in compat.OVERRIDES}
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path != COMPAT:
            found += violations(path, private, overrides, PACKAGE.parent)
    assert not found, "private Ray names outside rllib_asor/ray_compat.py: " + "; ".join(found)


def test_overrides_of_private_rllib_methods_are_listed_in_compat():
    """A class of ours that defines a private method of an RLlib base class it could extend
    must find the name in compat.OVERRIDES (so the version check covers it)."""
    from ray.rllib.algorithms.algorithm import Algorithm
    from ray.rllib.algorithms.algorithm_config import AlgorithmConfig
    from ray.rllib.algorithms.sac.sac_catalog import SACCatalog
    from ray.rllib.connectors.connector_v2 import ConnectorV2
    from ray.rllib.core.learner.torch.torch_learner import TorchLearner
    from ray.rllib.core.rl_module.torch.torch_rl_module import TorchRLModule

    bases = (Algorithm, AlgorithmConfig, SACCatalog, ConnectorV2, TorchLearner, TorchRLModule)
    rllib_private = {
        n for b in bases for n in dir(b) if n.startswith("_") and not n.startswith("__")
    }
    assert {"_update", "_get_tensor_variable", "_check_component"} <= rllib_private
    unlisted = [
        f"{path.relative_to(PACKAGE.parent)}:{line}"
        for path in sorted(PACKAGE.rglob("*.py"))
        for line in unlisted_overrides(path.read_text(), rllib_private)
    ]
    assert not unlisted, "overrides of private RLlib methods not in compat.OVERRIDES: " + (
        "; ".join(unlisted)
    )


def test_the_scan_finds_an_access(tmp_path):
    src = tmp_path / "x.py"
    src.write_text(
        "from ray.tune.registry import _global_registry\n"
        "def f(config, learner):\n"
        "    learner._update({})\n"
        "    return config._learner_class, getattr(learner, '_learner_connector')\n"
        "class L:\n"
        "    def _update(self, batch):\n"
        "        return super()._update(batch)\n"
    )
    found = violations(src, _private_names(), {p.name for p in compat.OVERRIDES}, tmp_path)
    names = sorted(f.split(" ")[1] for f in found)
    assert names == ["_global_registry", "_learner_class", "_learner_connector", "_update"]


def test_the_override_check_finds_an_unlisted_one():
    source = (
        "class L:\n"
        "    def _update(self):\n"
        "        pass\n"
        "    def _get_tensor_variable(self):\n"
        "        pass\n"
    )
    assert unlisted_overrides(source, {"_update", "_get_tensor_variable"}) == [
        "4 _get_tensor_variable"
    ]


def rllib_private_names() -> set[str]:
    """Private names RLlib's own source defines: `self._x = ...` and `def _x(`."""
    found: set[str] = set()
    for path in (Path(ray.__file__).parent / "rllib").rglob("*.py"):
        text = path.read_text(errors="ignore")
        found |= set(re.findall(r"self\.(_[a-z]\w*)\s*(?::[^=\n]*)?=[^=]", text))
        found |= set(re.findall(r"def (_[a-z]\w*)\(", text))
    return found


def names_we_define(trees: list[ast.AST]) -> set[str]:
    """Every name our package binds: functions, classes, stored attributes, variables, args."""
    out: set[str] = set()
    for tree in trees:
        for n in ast.walk(tree):
            if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                out.add(n.name)
            elif isinstance(n, ast.Attribute) and isinstance(n.ctx, ast.Store):
                out.add(n.attr)
            elif isinstance(n, ast.Name) and isinstance(n.ctx, ast.Store):
                out.add(n.id)
            elif isinstance(n, ast.arg):
                out.add(n.arg)
    return out


def test_no_attribute_only_rllib_defines_privately_is_read_outside_compat():
    """Beyond the listed names: an attribute `x._name` (on any object, `self` too) where RLlib
    defines `_name` and our package never does, is RLlib's private state (this finds 32 of
    the accesses the package had before compat, from no list)."""
    trees = {p: ast.parse(p.read_text()) for p in sorted(PACKAGE.rglob("*.py"))}
    theirs = rllib_private_names() - names_we_define(list(trees.values()))
    theirs -= {p.name for p in compat.OVERRIDES}
    assert {"_temp_losses", "_learner_connector", "_num_covered_epochs"} <= theirs
    found = [
        f"{path.relative_to(PACKAGE.parent)}:{n.lineno} {n.attr}"
        for path, tree in trees.items()
        if path != COMPAT
        for n in ast.walk(tree)
        if isinstance(n, ast.Attribute) and n.attr in theirs
    ]
    assert not found, "RLlib's private attributes outside rllib_asor/ray_compat.py: " + (
        "; ".join(found)
    )
