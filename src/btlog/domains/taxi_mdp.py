"""The Taxi world of Han et al. (section 7.2) as a deterministic MDP: the grid, its
optimal policy by value iteration, the human-expectation policy (the toll ignored),
rollouts, and an ASCII drawing of the grid. ``btlog.domains.taxi_world`` describes the
default world and turns policies into trees.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field, replace
from functools import cached_property
from types import MappingProxyType
from typing import NamedTuple

Cell = tuple[int, int]
"""A grid cell as ``(row, column)``, both numbered from 1; row 1 is the bottom row."""

MOVES: Mapping[str, tuple[int, int]] = MappingProxyType(
    {
        "move up": (1, 0),
        "move down": (-1, 0),
        "move left": (0, -1),
        "move right": (0, 1),
    }
)
"""The four move actions and the ``(row, column)`` change each one makes."""

PICK_UP = "pick up"
"""The action that takes the passenger into the taxi."""

DROP_OFF = "drop off"
"""The action that lets the passenger out of the taxi."""

ACTIONS: tuple[str, ...] = (*MOVES, PICK_UP, DROP_OFF)
"""Every action, in the fixed order used to break ties between equally good actions:
``move up, move down, move left, move right, pick up, drop off``. The strings are also the
behavior tree's action IDs."""


class TaxiState(NamedTuple):
    """Where the taxi is and where the passenger is.

    While ``in_taxi`` and ``delivered`` are both false the passenger waits at the world's
    passenger cell. ``delivered`` states are terminal: the episode is over.
    """

    row: int
    col: int
    in_taxi: bool = False
    delivered: bool = False

    @property
    def cell(self) -> Cell:
        """The taxi's cell as ``(row, column)``."""
        return (self.row, self.col)


def _as_cell(value: Iterable[int]) -> Cell:
    row, col = value
    return (int(row), int(col))


@dataclass(frozen=True)
class TaxiWorld:
    """One Taxi-domain instance: the grid, where everyone is, and the rewards.

    ``walls`` holds pairs of orthogonally adjacent cells that the taxi cannot drive between;
    the grid's border is always a wall. ``tolls`` maps a cell to the (negative) reward charged
    each time the taxi drives into it; either a mapping or pairs ``(cell, reward)`` may be
    given, and both fields are normalised (walls as sorted pairs, tolls as a sorted tuple).

    Rewards of one action: every action costs ``step_cost``; a move that enters a toll cell adds
    that cell's toll (a move that bumps into a wall or the border leaves the taxi in place and
    charges no toll); a legal ``pick up`` adds ``pickup_reward`` and a legal ``drop off`` (at the
    destination, passenger aboard) adds ``dropoff_reward``; an illegal pick up or drop off adds
    ``illegal_penalty`` and changes nothing. Future rewards are discounted by ``gamma``.
    """

    width: int
    height: int
    start: Cell
    passenger: Cell
    destination: Cell
    walls: frozenset[tuple[Cell, Cell]] = frozenset()
    tolls: tuple[tuple[Cell, float], ...] = ()
    step_cost: float = -1.0
    pickup_reward: float = 0.0
    dropoff_reward: float = 20.0
    illegal_penalty: float = -10.0
    gamma: float = 0.95
    _toll_by_cell: dict[Cell, float] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        """Check the world and normalise cells, walls and tolls."""
        if self.width < 1 or self.height < 1:
            raise ValueError(f"grid must be at least 1x1, got {self.width}x{self.height}")
        if not 0.0 < self.gamma <= 1.0:
            raise ValueError(f"gamma must be in (0, 1], got {self.gamma}")
        for name in ("start", "passenger", "destination"):
            cell = _as_cell(getattr(self, name))
            self._check_cell(cell, name)
            object.__setattr__(self, name, cell)
        walls = set()
        for pair in self.walls:
            a, b = (_as_cell(c) for c in pair)
            self._check_cell(a, "wall")
            self._check_cell(b, "wall")
            if abs(a[0] - b[0]) + abs(a[1] - b[1]) != 1:
                raise ValueError(f"wall {a}-{b} must join two orthogonally adjacent cells")
            walls.add((min(a, b), max(a, b)))
        object.__setattr__(self, "walls", frozenset(walls))
        items = self.tolls.items() if isinstance(self.tolls, Mapping) else self.tolls
        tolls: dict[Cell, float] = {}
        for cell_value, reward in items:
            cell = _as_cell(cell_value)
            self._check_cell(cell, "toll")
            if cell in tolls:
                raise ValueError(f"toll cell {cell} given twice")
            tolls[cell] = float(reward)
        object.__setattr__(self, "tolls", tuple(sorted(tolls.items())))
        object.__setattr__(self, "_toll_by_cell", tolls)

    def _check_cell(self, cell: Cell, what: str) -> None:
        if not self.in_grid(cell):
            raise ValueError(
                f"{what} cell {cell} is outside the {self.height}-row x {self.width}-column grid"
            )

    def in_grid(self, cell: Cell) -> bool:
        """Whether ``cell`` lies on the grid (rows ``1..height``, columns ``1..width``)."""
        return 1 <= cell[0] <= self.height and 1 <= cell[1] <= self.width

    def blocked(self, a: Cell, b: Cell) -> bool:
        """Whether a wall stands between the adjacent cells ``a`` and ``b``."""
        return (min(a, b), max(a, b)) in self.walls

    def toll_at(self, cell: Cell) -> float:
        """The toll charged for driving into ``cell`` (0.0 where there is none)."""
        return self._toll_by_cell.get(cell, 0.0)

    def neighbour(self, cell: Cell, move: str) -> Cell | None:
        """The cell that ``move`` leads to from ``cell``, or None if a wall or the border blocks."""
        d_row, d_col = MOVES[move]
        target = (cell[0] + d_row, cell[1] + d_col)
        if not self.in_grid(target) or self.blocked(cell, target):
            return None
        return target

    def start_state(self) -> TaxiState:
        """The initial state ``S0``: taxi at ``start``, passenger waiting."""
        return TaxiState(*self.start)

    @cached_property
    def _states(self) -> tuple[TaxiState, ...]:
        return tuple(
            TaxiState(row, col, in_taxi, delivered)
            for in_taxi, delivered in ((False, False), (True, False), (False, True))
            for row in range(1, self.height + 1)
            for col in range(1, self.width + 1)
        )

    def states(self) -> tuple[TaxiState, ...]:
        """Every state: each cell with the passenger waiting, aboard, and delivered."""
        return self._states

    def is_terminal(self, state: TaxiState) -> bool:
        """Whether ``state`` ends the episode (the passenger has been delivered)."""
        return state.delivered

    def step(self, state: TaxiState, action: str) -> tuple[TaxiState, float]:
        """The deterministic transition: the next state and the reward of ``action`` in ``state``.

        A terminal state is absorbing: every action leaves it unchanged with reward 0.
        """
        if action not in ACTIONS:
            raise ValueError(f"unknown action {action!r}; expected one of {', '.join(ACTIONS)}")
        if not self.in_grid(state.cell):
            raise ValueError(f"state {state} is outside the grid")
        if state.delivered:
            return state, 0.0
        reward = self.step_cost
        if action in MOVES:
            target = self.neighbour(state.cell, action)
            if target is None:
                return state, reward
            return state._replace(row=target[0], col=target[1]), reward + self.toll_at(target)
        if action == PICK_UP:
            if not state.in_taxi and state.cell == self.passenger:
                return state._replace(in_taxi=True), reward + self.pickup_reward
            return state, reward + self.illegal_penalty
        if state.in_taxi and state.cell == self.destination:
            return state._replace(in_taxi=False, delivered=True), reward + self.dropoff_reward
        return state, reward + self.illegal_penalty

    def without_tolls(self) -> TaxiWorld:
        """The same world with every toll removed (the human's mental model of section 7.2.1)."""
        return replace(self, tolls=())


def default_world() -> TaxiWorld:
    """The paper's instance (Fig. 12): 4 columns x 3 rows, toll at row 2, column 3.

    The taxi starts at row 1, column 1, which is also the destination; the passenger waits at
    row 3, column 3. A wall between columns 2 and 3 in rows 2 and 3 leaves two ways to the
    passenger: through the toll (4 moves) or around it through column 4 (6 moves). With a step
    cost of -1, a toll of -10 and a delivery reward of +20 (gamma 0.95) the optimal policy is the
    detour, i.e. exactly the action sequence of the paper's ``taxi-domain-tree.xml``.
    """
    return TaxiWorld(
        width=4,
        height=3,
        start=(1, 1),
        passenger=(3, 3),
        destination=(1, 1),
        walls=frozenset({((2, 2), (2, 3)), ((3, 2), (3, 3))}),
        tolls=(((2, 3), -10.0),),
    )


class Policy(Mapping[TaxiState, str]):
    """A deterministic policy: a read-only mapping from each non-terminal state to an action.

    ``value_table`` holds the state values the policy was derived from (empty if none).
    """

    def __init__(
        self,
        actions: Mapping[TaxiState, str],
        value_table: Mapping[TaxiState, float] | None = None,
    ) -> None:
        """Wrap ``actions`` (state -> action) and, optionally, the value table behind them."""
        self._actions = dict(actions)
        self.value_table: Mapping[TaxiState, float] = MappingProxyType(dict(value_table or {}))

    def __getitem__(self, state: TaxiState) -> str:
        """The action taken in ``state``."""
        return self._actions[state]

    def __iter__(self) -> Iterator[TaxiState]:
        """The states the policy covers."""
        return iter(self._actions)

    def __len__(self) -> int:
        """How many states the policy covers."""
        return len(self._actions)

    def __repr__(self) -> str:
        """A short description."""
        return f"Policy({len(self)} states)"


def value_iteration(
    world: TaxiWorld, tolerance: float = 1e-9, max_iterations: int = 100_000
) -> Policy:
    """The optimal policy of ``world`` by value iteration, with its value table.

    Bellman backups ``V(s) = max_a r(s, a) + gamma * V(T(s, a))`` run over all non-terminal
    states at once (terminal states keep value 0) until no value changes by ``tolerance`` or
    more. The policy is greedy in the final values; actions whose values lie within
    ``tolerance`` of the best count as tied, and the first of them in :data:`ACTIONS` order wins,
    so the result is deterministic.
    """
    if tolerance <= 0:
        raise ValueError(f"tolerance must be positive, got {tolerance}")
    gamma = world.gamma
    live = [s for s in world.states() if not world.is_terminal(s)]
    transitions = {s: [(a, *world.step(s, a)) for a in ACTIONS] for s in live}
    values = dict.fromkeys(world.states(), 0.0)
    for _ in range(max_iterations):
        new = {s: max(r + gamma * values[n] for _, n, r in transitions[s]) for s in live}
        delta = max((abs(new[s] - values[s]) for s in live), default=0.0)
        values.update(new)
        if delta < tolerance:
            break
    else:
        raise RuntimeError(f"value iteration did not converge in {max_iterations} iterations")
    actions = {}
    for s in live:
        q = [(a, r + gamma * values[n]) for a, n, r in transitions[s]]
        best = max(v for _, v in q)
        actions[s] = next(a for a, v in q if v >= best - tolerance)
    return Policy(actions, values)


def human_expectation_policy(world: TaxiWorld, tolerance: float = 1e-9) -> Policy:
    """What a person expects the taxi to do: the optimal policy with the tolls' cost ignored.

    The person of section 7.2.1 underestimates the toll, so this runs :func:`value_iteration`
    on :meth:`TaxiWorld.without_tolls`. Without tolls every step costs the same, so the result
    is a shortest path by number of steps (ties broken in :data:`ACTIONS` order) -- in the
    default world the straight path through the toll at row 2, column 3.
    """
    return value_iteration(world.without_tolls(), tolerance)


def trace(world: TaxiWorld, actions: Iterable[str]) -> list[TaxiState]:
    """The states visited when ``actions`` are taken from the start: ``len(actions) + 1`` states."""
    state = world.start_state()
    states = [state]
    for action in actions:
        state, _ = world.step(state, action)
        states.append(state)
    return states


def discounted_return(world: TaxiWorld, actions: Iterable[str]) -> float:
    """The discounted sum of rewards, ``sum_t gamma**t * r_t``, of ``actions`` from the start."""
    state = world.start_state()
    total, discount = 0.0, 1.0
    for action in actions:
        state, reward = world.step(state, action)
        total += discount * reward
        discount *= world.gamma
    return total


def rollout(world: TaxiWorld, policy: Mapping[TaxiState, str], max_steps: int = 100) -> list[str]:
    """The actions ``policy`` takes from the start state until the passenger is delivered.

    Raises RuntimeError if the passenger is not delivered within ``max_steps`` actions.
    """
    state = world.start_state()
    actions: list[str] = []
    while not world.is_terminal(state):
        if len(actions) >= max_steps:
            raise RuntimeError(f"passenger not delivered within {max_steps} steps")
        action = policy[state]
        actions.append(action)
        state, _ = world.step(state, action)
    return actions


def render_grid(world: TaxiWorld) -> str:
    """An ASCII drawing of ``world``: row 1 at the bottom, walls as ``|`` and ``---``.

    Cells are labelled ``T`` (taxi start), ``P`` (passenger), ``D`` (destination), ``$`` (toll).
    """

    def label(cell: Cell) -> str:
        marks = [
            mark
            for mark, here in (
                ("T", world.start),
                ("P", world.passenger),
                ("D", world.destination),
            )
            if here == cell
        ]
        return "".join(marks) + ("$" if world.toll_at(cell) else "")

    cells = [(r, c) for r in range(1, world.height + 1) for c in range(1, world.width + 1)]
    w = max(3, *(len(label(cell)) + 2 for cell in cells))
    pad = len(str(world.height)) + 2

    def boundary(upper: int) -> str:
        # the line between rows ``upper`` and ``upper - 1``; upper = height + 1 or 1: the border
        parts = []
        for col in range(1, world.width + 1):
            border = upper in (1, world.height + 1)
            wall = border or world.blocked((upper, col), (upper - 1, col))
            parts.append(("-" if wall else " ") * w)
        return " " * pad + "+" + "+".join(parts) + "+"

    header = " ".join(str(col).center(w) for col in range(1, world.width + 1))
    lines = [(" " * (pad + 1) + header).rstrip()]
    for row in range(world.height, 0, -1):
        lines.append(boundary(row + 1))
        text = f"{row:>{pad - 1}} |"
        for col in range(1, world.width + 1):
            text += label((row, col)).center(w)
            if col < world.width:
                text += "|" if world.blocked((row, col), (row, col + 1)) else " "
        lines.append(text + "|")
    lines.append(boundary(1))
    return "\n".join(lines) + "\n"
