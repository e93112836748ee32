"""`{grid_search: [...]}` values in YAML: find them, pick candidates, turn them into Tune's form."""

from __future__ import annotations

import copy
from collections.abc import Iterator
from typing import Any

Path = tuple[str, ...]


def is_grid(value: Any) -> bool:
    """True for the YAML form `{grid_search: [v1, v2, ...]}`."""
    return isinstance(value, dict) and set(value) == {"grid_search"}


def find_grids(tree: Any, prefix: Path = ()) -> Iterator[tuple[Path, list[Any]]]:
    """Yield (path, candidates) for every grid_search value inside nested dicts."""
    if is_grid(tree):
        yield prefix, tree["grid_search"]
        return
    if isinstance(tree, dict):
        for key, value in tree.items():
            yield from find_grids(value, (*prefix, str(key)))


def get_path(tree: dict[str, Any], path: Path) -> Any:
    for key in path:
        tree = tree[key]
    return tree


def set_path(tree: dict[str, Any], path: Path, value: Any) -> None:
    """Set `tree[path]`, creating intermediate dicts."""
    for key in path[:-1]:
        nxt = tree.get(key)
        if not isinstance(nxt, dict):
            nxt = {}
            tree[key] = nxt
        tree = nxt
    tree[path[-1]] = value


def with_candidates(tree: dict[str, Any], choice: dict[Path, Any] | None = None) -> dict[str, Any]:
    """Deep copy of `tree` with each grid replaced by `choice[path]` (default: first candidate)."""
    choice = choice or {}
    out = copy.deepcopy(tree)
    for path, candidates in list(find_grids(tree)):
        set_path(out, path, choice.get(path, candidates[0]))
    return out


def to_tune(tree: Any) -> Any:
    """Copy of `tree` with each YAML grid turned into `tune.grid_search([...])`."""
    from ray import tune

    if is_grid(tree):
        return tune.grid_search(list(tree["grid_search"]))
    if isinstance(tree, dict):
        return {k: to_tune(v) for k, v in tree.items()}
    return copy.deepcopy(tree)


def count_trials(*trees: Any) -> int:
    """Number of grid combinations in the given trees."""
    n = 1
    for tree in trees:
        for _, candidates in find_grids(tree):
            n *= len(candidates)
    return n
