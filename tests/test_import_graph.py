"""No import cycles inside `rllib_asor` or `game_env`.

Every module's imports are read statically (ast), function-local and ``TYPE_CHECKING`` ones
included, so a cycle hidden behind a local import still counts. ``from pkg import name`` is an
edge to ``pkg.name`` when that is a module, else to ``pkg``; importing ``a.b`` is an edge to
``a.b`` only (not to the ``a/__init__`` that Python also runs), so a package's ``__init__``
re-exporting its modules is not a cycle by itself.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("rllib_asor", "game_env")


def modules(package: str) -> dict[str, Path]:
    """Dotted module name -> file, for every .py file of ``package``."""
    out = {}
    for path in sorted((ROOT / package).rglob("*.py")):
        parts = path.relative_to(ROOT).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def imports(name: str, path: Path, known: set[str]) -> set[str]:
    """The modules of ``known`` that module ``name`` (at ``path``) imports anywhere."""
    is_pkg = path.name == "__init__.py"
    here = name if is_pkg else name.rpartition(".")[0]
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = here.split(".")
                base = base[: len(base) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            targets = [f"{mod}.{a.name}" if f"{mod}.{a.name}" in known else mod for a in node.names]
        else:
            continue
        for t in targets:
            while t and t not in known:  # `import a.b.c` where only a.b is ours, ...
                t = t.rpartition(".")[0]
            if t:
                out.add(t)
    return out


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module, or a module importing itself."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:  # Tarjan
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1 or v in graph[v]:
                found.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def import_graph(package: str) -> dict[str, set[str]]:
    mods = modules(package)
    known = set(mods)
    return {name: imports(name, path, known) for name, path in mods.items()}


@pytest.mark.parametrize("package", PACKAGES)
def test_no_import_cycle(package):
    graph = import_graph(package)
    assert len(graph) > 5
    found = cycles(graph)
    assert not found, f"import cycles in {package}: {found}"


def test_the_walk_sees_local_imports_and_finds_cycles(tmp_path, monkeypatch):
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("from pkg.a import f\n")
    (pkg / "a.py").write_text("from pkg import b\n\ndef f():\n    return b\n")
    (pkg / "b.py").write_text("def g():\n    from .a import f\n    return f\n")
    (pkg / "c.py").write_text("import pkg.a\n")
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    graph = import_graph("pkg")
    assert graph == {"pkg": {"pkg.a"}, "pkg.a": {"pkg.b"}, "pkg.b": {"pkg.a"}, "pkg.c": {"pkg.a"}}
    assert cycles(graph) == [["pkg.a", "pkg.b"]]


# Layers, top to bottom: a module may import its own layer and the layers below, never above.
LAYERS = [
    ("rllib_asor.cli",),
    ("rllib_asor.report",),
    ("rllib_asor.rllib", "rllib_asor.registry"),  # ASOR glue, env ids for Tune
    ("rllib_asor.algorithms", "rllib_asor.race", "rllib_asor.data"),
    ("rllib_asor.evaluation",),
    ("rllib_asor.asor", "rllib_asor.envs", "game_env"),
    # the one wall around Ray's private names; the pydantic base of every settings block
    ("rllib_asor.ray_compat", "rllib_asor.settings_model"),
]


def _layer(module: str) -> int | None:
    for depth, prefixes in enumerate(LAYERS):
        if any(module == p or module.startswith(p + ".") for p in prefixes):
            return depth
    return None


def test_imports_point_down_the_layers():
    graph = {**import_graph("rllib_asor"), **import_graph("game_env")}
    upward = []
    for module, targets in graph.items():
        here = _layer(module)
        for target in targets:
            there = _layer(target)
            if here is not None and there is not None and there < here:
                upward.append(f"{module} -> {target}")
    assert not upward, f"imports from a lower layer to a higher one: {upward}"


def test_algorithms_know_nothing_of_asor_and_the_core_no_ray():
    graph = import_graph("rllib_asor")
    for module, targets in graph.items():
        if module.startswith("rllib_asor.algorithms"):
            assert not {
                t for t in targets if t.startswith(("rllib_asor.rllib", "rllib_asor.asor"))
            }, module
    for module, path in modules("rllib_asor").items():
        if module.startswith(("rllib_asor.asor", "rllib_asor.envs")):
            tree = ast.parse(path.read_text())
            names = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
            names |= {n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
            assert not {n for n in names if n == "ray" or n.startswith("ray.")}, module


OUTSIDE = ("studies", "benchmarks")


def outside_imports(path: Path) -> list[str]:
    """Imports of the studies' or benchmarks' code in one file: `import` / `from` statements
    (local ones too) and `importlib.import_module` / `spec_from_file_location` on their paths."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and not node.level:
            names = [node.module or ""]
        elif isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", "")) in (
            "import_module",
            "spec_from_file_location",
        ):
            names = [
                a.value.replace("/", ".")
                for a in ast.walk(node)
                if isinstance(a, ast.Constant) and isinstance(a.value, str)
            ]
        found += [f"{path.name}: {n}" for n in names if n.split(".")[0] in OUTSIDE]
    return found


def test_the_package_tests_import_no_study_or_benchmark():
    """The package's tests stand alone: a study's or benchmark's tests live beside it."""
    files = sorted((ROOT / "tests").rglob("*.py"))
    assert len(files) > 20
    assert [hit for path in files for hit in outside_imports(path)] == []


def test_the_outside_import_check_sees_each_form(tmp_path):
    bad = tmp_path / "test_bad.py"
    bad.write_text(
        "import studies.lib.compare\n"
        "def f():\n    from benchmarks.common import write_json\n"
        "import importlib\nimportlib.import_module('benchmarks.maple_speed')\n"
        "importlib.util.spec_from_file_location('x', 'studies/escp_walker/summarise.py')\n"
        "import rllib_asor\n"
    )
    assert len(outside_imports(bad)) == 4
