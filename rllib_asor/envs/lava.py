"""Lava world: the ASOR paper's motivating cross-dynamics gridworld (Sec. 3.1 / Appendix).

A 7x7 grid. The agent starts at S and must reach G. One lava block is fixed on row 1; a second,
two cells wide, lies on a row k drawn from {2, 3, 4, 5} at every reset (the *dynamics*: which
cells are lava). The agent sees only (row, col, flag), where flag = 1 when a lava cell is in its
4-neighbourhood ("lava within one step"); it never sees k.

Layout "B" (default; derived from the facts the paper states)::

         c0 c1 c2 c3 c4 c5 c6
    r0    .  .  .  .  S  .  .      S=(0,4)  G=(5,6)
    r1    .  .  .  .  .  F  F      F: fixed lava (1,5),(1,6)
    r2    .  .  .  . M2 M2  .      Mk: lava at (k,4),(k,5), k drawn per episode
    r3    .  .  .  . M3 M3  .
    r4    .  .  .  . M4 M4  .
    r5    .  .  .  . M5 M5  G
    r6    .  .  .  .  .  .  .

Layout "E" is the same grid with S=(0,3).

Rewards: -0.02 on every step (the goal step included), +1 on reaching G. The episode ends on
lava or G (terminated) or after ``max_steps`` = 50 steps (truncated). Moving into the border
leaves the agent in place. Actions: 0 up, 1 right, 2 down, 3 left.

Why the optimal route depends on k (checked by value iteration in tests/envs/test_lava.py):
with k known, the shortest safe route of layout B is 7 steps (return 0.86) for k = 3, 4, 5 but
9 steps (0.82) for k = 2, and for k = 3 the only 7-step route crosses row 2 at (2,4),(2,5) --
lava when k = 2. A memoryless policy on (row, col, flag) can tell k = 2 only next to (2,4), so
its best is 0.82 under every k (exhaustive search: `best_reactive_returns`).

Helpers for benchmarks/reports: `LavaWorldEnv.cells`, `LavaWorldEnv.observation_at`
(the observation at a cell under a lava row, e.g. for a pseudo-count heatmap),
`optimal_return` (value iteration, k known), `optimal_routes`, `best_reactive_returns` and
`best_reactive_policy`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from functools import cache
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

Cell = tuple[int, int]

GRID_SIZE = 7
FIXED_LAVA: tuple[Cell, ...] = ((1, 5), (1, 6))
MOVING_LAVA_COLS: tuple[int, ...] = (4, 5)
LAVA_ROWS: tuple[int, ...] = (2, 3, 4, 5)
GOAL: Cell = (5, 6)
STARTS: dict[str, Cell] = {"B": (0, 4), "E": (0, 3)}
STEP_REWARD = -0.02
GOAL_REWARD = 1.0
MAX_STEPS = 50
OBS_MODES = ("onehot", "raw")
# action -> (d_row, d_col): up, right, down, left
MOVES: tuple[Cell, ...] = ((-1, 0), (0, 1), (1, 0), (0, -1))


def _check_lava_row(lava_row: Any, key: str = "lava_row") -> int:
    if isinstance(lava_row, bool) or not isinstance(lava_row, (int, np.integer)):
        raise ValueError(f"{key}={lava_row!r} is not allowed; expected an int in {LAVA_ROWS}")
    if int(lava_row) not in LAVA_ROWS:
        raise ValueError(f"{key}={lava_row!r} is not allowed; expected one of {LAVA_ROWS}")
    return int(lava_row)


def _check_layout(layout: Any) -> str:
    if layout not in STARTS:
        raise ValueError(f"layout={layout!r} is not allowed; expected one of {tuple(STARTS)}")
    return layout


def _check_cell(row: Any, col: Any) -> Cell:
    for key, value in (("row", row), ("col", col)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise ValueError(
                f"{key}={value!r} is not allowed; expected an int in [0, {GRID_SIZE - 1}]"
            )
        if not 0 <= int(value) < GRID_SIZE:
            raise ValueError(
                f"{key}={value!r} is not allowed; expected an int in [0, {GRID_SIZE - 1}]"
            )
    return int(row), int(col)


def lava_cells(lava_row: int) -> frozenset[Cell]:
    """All lava cells when the moving block is on `lava_row`."""
    lava_row = _check_lava_row(lava_row)
    return frozenset(FIXED_LAVA) | {(lava_row, c) for c in MOVING_LAVA_COLS}


def move(cell: Cell, action: int) -> Cell:
    """The cell reached from `cell` by `action`; the border keeps the agent in place."""
    dr, dc = MOVES[action]
    r, c = cell[0] + dr, cell[1] + dc
    if 0 <= r < GRID_SIZE and 0 <= c < GRID_SIZE:
        return r, c
    return cell


def lava_flag(row: int, col: int, lava_row: int) -> bool:
    """True when a lava cell is in the 4-neighbourhood of (row, col)."""
    lava = lava_cells(lava_row)
    return any((row + dr, col + dc) in lava for dr, dc in MOVES)


def observation_at(row: int, col: int, lava_row: int, obs_mode: str = "onehot") -> np.ndarray:
    """The observation an agent at (row, col) receives when the moving lava is on `lava_row`."""
    row, col = _check_cell(row, col)
    lava_row = _check_lava_row(lava_row)
    flag = float(lava_flag(row, col, lava_row))
    if obs_mode == "onehot":
        obs = np.zeros(2 * GRID_SIZE + 1, dtype=np.float32)
        obs[row] = 1.0
        obs[GRID_SIZE + col] = 1.0
        obs[-1] = flag
        return obs
    if obs_mode == "raw":
        return np.array([row, col, flag], dtype=np.float32)
    raise ValueError(f"obs_mode={obs_mode!r} is not allowed; expected one of {OBS_MODES}")


def free_cells(lava_row: int | None = None) -> list[Cell]:
    """Cells that are not lava: under `lava_row` if given, else all but the fixed lava."""
    lava = set(FIXED_LAVA) if lava_row is None else set(lava_cells(lava_row))
    return [(r, c) for r in range(GRID_SIZE) for c in range(GRID_SIZE) if (r, c) not in lava]


@cache
def _values(lava_row: int, max_steps: int) -> tuple[tuple[dict[Cell, float], ...], frozenset[Cell]]:
    """Finite-horizon value iteration with k known: V[t][cell] = best return from step t."""
    lava = lava_cells(lava_row)
    cells = free_cells(lava_row)
    values: list[dict[Cell, float]] = [dict.fromkeys(cells, 0.0)]  # V at t = max_steps
    for _ in range(max_steps):
        nxt = values[-1]
        cur: dict[Cell, float] = {}
        for cell in cells:
            if cell == GOAL:
                cur[cell] = 0.0  # absorbing (episode already over)
                continue
            best = -np.inf
            for a in range(len(MOVES)):
                n = move(cell, a)
                q = STEP_REWARD + (GOAL_REWARD if n == GOAL else 0.0)
                if n not in lava and n != GOAL:
                    q += nxt[n]
                best = max(best, q)
            cur[cell] = best
        values.append(cur)
    values.reverse()  # values[t] = value with t steps already taken
    return tuple(values), lava


def optimal_return(lava_row: int, layout: str = "B", max_steps: int = MAX_STEPS) -> float:
    """Best episode return from the start when the lava row is known (value iteration)."""
    lava_row = _check_lava_row(lava_row)
    values, _ = _values(lava_row, max_steps)
    return float(round(values[0][STARTS[_check_layout(layout)]], 10))


def optimal_routes(
    lava_row: int, layout: str = "B", max_steps: int = MAX_STEPS
) -> list[list[Cell]]:
    """Every optimal route (list of cells, start to goal) when the lava row is known."""
    lava_row = _check_lava_row(lava_row)
    values, lava = _values(lava_row, max_steps)
    start = STARTS[_check_layout(layout)]
    routes: list[list[Cell]] = []

    def expand(route: list[Cell]) -> None:
        t, cell = len(route) - 1, route[-1]
        if cell == GOAL:
            routes.append(route)
            return
        for a in range(len(MOVES)):
            n = move(cell, a)
            q = STEP_REWARD + (GOAL_REWARD if n == GOAL else 0.0)
            if n not in lava and n != GOAL:
                q += values[t + 1][n]
            if n not in lava and abs(q - values[t][cell]) < 1e-9 and n not in route:
                expand(route + [n])

    expand([start])
    return routes


def best_reactive_returns(
    layout: str = "B", lava_rows: Sequence[int] = LAVA_ROWS, max_steps: int = MAX_STEPS
) -> dict[int, float]:
    """Per-row returns of the best deterministic memoryless policy on (row, col, flag).

    Exhaustive branch-and-bound over policies (the mean return over `lava_rows` is maximised);
    this is the best an agent that only sees the observation can do. Cached; takes a few s.
    """
    return dict(_best_reactive(_check_layout(layout), tuple(lava_rows), int(max_steps))[0])


def best_reactive_policy(
    layout: str = "B", lava_rows: Sequence[int] = LAVA_ROWS, max_steps: int = MAX_STEPS
) -> dict[tuple[int, int, bool], int]:
    """The policy behind `best_reactive_returns`: (row, col, flag) -> action, visited obs only."""
    return dict(_best_reactive(_check_layout(layout), tuple(lava_rows), int(max_steps))[1])


def reactive_expert(layout: str = "B", obs_mode: str = "onehot") -> Callable[[np.ndarray], int]:
    """`best_reactive_policy` as a policy on this env's observations (`obs_mode`): obs →
    action, e.g. to record an expert's demonstrations for the imitation-from-observation
    baselines. An observation the policy never visits gets action 1 (one column right)."""
    policy = best_reactive_policy(layout)
    if obs_mode not in OBS_MODES:
        raise ValueError(f"obs_mode={obs_mode!r} is not allowed; expected one of {OBS_MODES}")

    def act(obs: np.ndarray) -> int:
        if obs_mode == "onehot":
            row, col = int(np.argmax(obs[:GRID_SIZE])), int(np.argmax(obs[GRID_SIZE:-1]))
        else:
            row, col = int(obs[0]), int(obs[1])
        return int(policy.get((row, col, bool(obs[-1] > 0.5)), 1))

    return act


@cache
def _best_reactive(
    layout: str, lava_rows: tuple[int, ...], max_steps: int
) -> tuple[dict[int, float], dict[tuple[int, int, bool], int]]:
    start = STARTS[_check_layout(layout)]
    rows = tuple(sorted({_check_lava_row(k, "lava_rows") for k in lava_rows}))  # 2 first: fastest
    lavas = {k: lava_cells(k) for k in rows}
    # steps-to-goal with k known (from value iteration) for the optimistic bound
    vals = {k: _values(k, max_steps)[0][0] for k in rows}
    loop_return = STEP_REWARD * max_steps
    best: dict[str, Any] = {"total": -np.inf, "returns": None}

    flags = {k: {c: lava_flag(c[0], c[1], k) for c in free_cells(k)} for k in rows}

    def obs(cell: Cell, k: int) -> tuple[int, int, bool]:
        return cell[0], cell[1], flags[k][cell]

    def _q(v: dict[Cell, float], lava: frozenset[Cell], cell: Cell, a: int) -> float:
        n = move(cell, a)
        if n == GOAL:
            return STEP_REWARD + GOAL_REWARD
        return STEP_REWARD if n in lava else STEP_REWARD + v[n]

    def bound(state: dict[int, Any]) -> float:
        total = 0.0
        for k, (cell, ret, _visited, done) in state.items():
            total += ret if done else ret + vals[k].get(cell, loop_return)
        return total

    def search(state: dict[int, Any], policy: dict[tuple[int, int, bool], int]) -> None:
        if bound(state) <= best["total"] + 1e-12:
            return
        active = [k for k, s in state.items() if not s[3]]
        if not active:
            total = sum(s[1] for s in state.values())
            best["total"], best["policy"] = total, policy
            best["returns"] = {k: round(s[1], 10) for k, s in state.items()}
            return
        k = active[0]
        cell, ret, visited, _ = state[k]
        o = obs(cell, k)
        actions = (
            [policy[o]]
            if o in policy
            else sorted(range(len(MOVES)), key=lambda a: -_q(vals[k], lavas[k], cell, a))
        )
        for a in actions:
            n = move(cell, a)
            new = dict(state)
            steps = len(visited)
            if n in lavas[k]:
                new[k] = (n, ret + STEP_REWARD, visited, True)
            elif n == GOAL:
                new[k] = (n, ret + STEP_REWARD + GOAL_REWARD, visited, True)
            elif n in visited or steps >= max_steps:
                # deterministic policy + deterministic dynamics: a revisit loops until the cap
                new[k] = (n, loop_return, visited, True)
            else:
                new[k] = (n, ret + STEP_REWARD, visited | {n}, False)
            if o in policy:
                search(new, policy)
            else:
                search(new, {**policy, o: a})

    search({k: (start, 0.0, frozenset({start}), False) for k in rows}, {})
    return best["returns"], best["policy"]


class LavaWorldEnv(gym.Env[np.ndarray, np.int64]):
    """Lava gridworld whose moving lava row (the dynamics) is drawn per episode.

    Args:
        lava_row: fix the moving lava on this row (one of 2..5); None draws it per episode.
        lava_rows: rows to draw from when `lava_row` is None.
        obs_mode: "onehot" (one-hot row, one-hot col, flag: 15 floats) or "raw" (3 floats).
        layout: "B" (start (0,4)) or "E" (start (0,3)).
        max_steps: episode cap (truncation).
        render_mode: None or "ansi".

    `reset(options={"lava_row": k})` fixes the row for one episode. Every `info` holds
    `dynamics_id` (= lava row), `lava_row`, `row`, `col`, `is_success`, `in_lava`,
    `reward_step`, `reward_goal` (their sum is the reward).
    """

    metadata = {"render_modes": ["ansi"], "render_fps": 4}

    def __init__(
        self,
        lava_row: int | None = None,
        lava_rows: Iterable[int] = LAVA_ROWS,
        obs_mode: str = "onehot",
        layout: str = "B",
        max_steps: int = MAX_STEPS,
        render_mode: str | None = None,
    ) -> None:
        if obs_mode not in OBS_MODES:
            raise ValueError(f"obs_mode={obs_mode!r} is not allowed; expected one of {OBS_MODES}")
        if render_mode not in (None, "ansi"):
            raise ValueError(f"render_mode={render_mode!r} is not allowed; expected None or 'ansi'")
        if (
            isinstance(max_steps, bool)
            or not isinstance(max_steps, (int, np.integer))
            or max_steps < 1
        ):
            raise ValueError(f"max_steps={max_steps!r} is not allowed; expected an int >= 1")
        rows = tuple(lava_rows)
        if not rows:
            raise ValueError(
                f"lava_rows={rows!r} is not allowed; expected a non-empty subset of {LAVA_ROWS}"
            )
        self.lava_rows = tuple(_check_lava_row(k, "lava_rows") for k in rows)
        self.fixed_lava_row = None if lava_row is None else _check_lava_row(lava_row)
        self.obs_mode = obs_mode
        self.layout = _check_layout(layout)
        self.start = STARTS[self.layout]
        self.max_steps = int(max_steps)
        self.render_mode = render_mode

        self.action_space = spaces.Discrete(len(MOVES))
        if obs_mode == "onehot":
            self.observation_space = spaces.Box(0.0, 1.0, (2 * GRID_SIZE + 1,), np.float32)
        else:
            high = np.array([GRID_SIZE - 1, GRID_SIZE - 1, 1], dtype=np.float32)
            self.observation_space = spaces.Box(np.zeros(3, np.float32), high, (3,), np.float32)

        self.lava_row = (
            self.fixed_lava_row if self.fixed_lava_row is not None else self.lava_rows[0]
        )
        self.cell: Cell = self.start
        self.steps = 0

    # -- helpers ------------------------------------------------------------------------------
    @staticmethod
    def cells(lava_row: int | None = None) -> list[Cell]:
        """Free (row, col) cells: not lava under `lava_row`, or not fixed lava if None."""
        return free_cells(lava_row)

    def observation_at(self, row: int, col: int, lava_row: int) -> np.ndarray:
        """The observation (in this env's obs_mode) at (row, col) under `lava_row`."""
        return observation_at(row, col, lava_row, self.obs_mode)

    def observation_grid(self, lava_row: int) -> tuple[list[Cell], np.ndarray]:
        """Free cells under `lava_row` and their observations stacked (n_cells, obs_dim)."""
        cells = free_cells(_check_lava_row(lava_row))
        return cells, np.stack([self.observation_at(r, c, lava_row) for r, c in cells])

    optimal_return = staticmethod(optimal_return)

    # -- gymnasium API --------------------------------------------------------------------------
    def _obs(self) -> np.ndarray:
        return observation_at(self.cell[0], self.cell[1], self.lava_row, self.obs_mode)

    def _info(self, reward_step: float = 0.0, reward_goal: float = 0.0) -> dict[str, Any]:
        lava = lava_cells(self.lava_row)
        return {
            "dynamics_id": self.lava_row,
            "lava_row": self.lava_row,
            "row": self.cell[0],
            "col": self.cell[1],
            "steps": self.steps,
            "is_success": self.cell == GOAL,
            "in_lava": self.cell in lava,
            "reward_step": reward_step,
            "reward_goal": reward_goal,
        }

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        options = options or {}
        unknown = set(options) - {"lava_row"}
        if unknown:
            raise ValueError(
                f"options keys {sorted(unknown)} are not allowed; expected only 'lava_row'"
            )
        if options.get("lava_row") is not None:
            self.lava_row = _check_lava_row(options["lava_row"])
        elif self.fixed_lava_row is not None:
            self.lava_row = self.fixed_lava_row
        else:
            self.lava_row = int(self.lava_rows[self.np_random.integers(len(self.lava_rows))])
        self.cell = self.start
        self.steps = 0
        return self._obs(), self._info()

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if not self.action_space.contains(action):
            raise ValueError(
                f"action={action!r} is not allowed; expected an int in [0, {len(MOVES) - 1}]"
            )
        self.cell = move(self.cell, int(action))
        self.steps += 1
        reward_goal = GOAL_REWARD if self.cell == GOAL else 0.0
        terminated = self.cell == GOAL or self.cell in lava_cells(self.lava_row)
        truncated = (not terminated) and self.steps >= self.max_steps
        reward = STEP_REWARD + reward_goal
        return self._obs(), reward, terminated, truncated, self._info(STEP_REWARD, reward_goal)

    def render(self) -> str | None:
        if self.render_mode != "ansi":
            return None
        lava = lava_cells(self.lava_row)
        lines = []
        for r in range(GRID_SIZE):
            row = []
            for c in range(GRID_SIZE):
                if (r, c) == self.cell:
                    row.append("A")
                elif (r, c) in lava:
                    row.append("L")
                elif (r, c) == GOAL:
                    row.append("G")
                else:
                    row.append(".")
            lines.append(" ".join(row))
        return "\n".join(lines) + "\n"
