"""Linear inequality constraints on a command, and the command nearest a given one under them.

A limit gives, for this cycle, rows ``G x ≤ h`` on the command ``x`` (a :class:`Constraint`,
named for diagnostics) and a period's box ``lower ≤ x ≤ upper`` (a :class:`Box`, kept as
bounds). Several constraints stack into one (:meth:`Constraint.stack`), which remembers how
many rows each contributed, so the answer can say which limits bind
(:meth:`Constraint.binding`). :func:`nearest` is the one QP every such problem goes through:
the command nearest a given one in a metric, under the stacked rows and within the box,
through a maintained solver (DAQP, its own Python interface); where the rows conflict within
the box, the same solver takes the problem again with the rows soft (DAQP's soft constraints:
a slack per row at a cost).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import NamedTuple

import daqp
import numpy as np
from numpy.typing import ArrayLike

from wmm_control.errors import NonFiniteError, ShapeError

__all__ = ['Constraint', 'Box', 'Nearest', 'nearest', 'MEETABLE_COST', 'SLACK_COST', 'SLACK_WEIGHT', 'TOLERANCE']

#: DAQP's ``sense`` flag of a soft row (one it may break, at a cost).
_SOFT = 8
#: Cost per unit of row slack, linear (an exact penalty: no slack at all where the box leaves
#: room, which a quadratic cost would not give), against weights of about 1 on the command;
#: and its small quadratic term (½ SLACK_WEIGHT s²), which keeps the relaxed problem strictly
#: convex.
SLACK_COST = 1e3
SLACK_WEIGHT = 1.0
#: How many times :data:`SLACK_COST` the slack of a row costs where some command in the box meets
#: that row on its own: a row the box has to break anyway (a pair that arrives faster than its
#: acceleration limits can brake) is met as far as it can be, but not at the price of breaking a
#: row the box could keep (unless a hundred such rows pull against that one). With one cost for
#: all, rows of one side outvoted the other: on ``ur_mecanum`` in ``clutter`` (goal 51, ``pinv``),
#: up to eleven rows of the swinging arm's links that no command in the box met had the base driven
#: at its acceleration limit towards a box that its chassis' one row asked it away from, while that
#: row could still be met, and the chassis went 4.5 mm into the box before the base could brake.
MEETABLE_COST = 100.0
#: A row is taken as met (and, at equality, as binding) within this much.
TOLERANCE = 1e-9


def _frozen(array: np.ndarray) -> np.ndarray:
    array.setflags(write=False)
    return array


@dataclass(frozen=True)
class Constraint:
    """Rows ``G x ≤ h`` on a command ``x`` of ``n`` entries.

    Attributes:
        G: Shape (m, n), finite.
        h: Shape (m,); no NaN and no −inf (+inf: a row that never binds).
        name: what the rows keep, for diagnostics.
        parts: ``(name, rows)`` of each constraint stacked into this one, in order (one part,
            this one's own name, when not stacked).

    Raises:
        ShapeError: ``G`` not 2-D, ``h`` not 1-D, or their rows differ in number.
        NonFiniteError: a non-finite entry of ``G``, a NaN or −inf in ``h``.
    """

    G: np.ndarray
    h: np.ndarray
    name: str = 'constraint'
    parts: tuple[tuple[str, int], ...] = field(default=())

    def __post_init__(self):
        G, h = np.asarray(self.G, dtype=float), np.asarray(self.h, dtype=float)
        if G.ndim != 2:
            raise ShapeError(f'constraint {self.name!r}: G must be 2-D (m, n), got shape {G.shape}')
        if h.shape != (G.shape[0],):
            raise ShapeError(f'constraint {self.name!r}: h must have shape ({G.shape[0]},), got {h.shape}')
        if not np.isfinite(G).all():
            raise NonFiniteError(f'constraint {self.name!r}: non-finite entries in G')
        if not (h > -np.inf).all():  # NaN compares false too
            raise NonFiniteError(f'constraint {self.name!r}: NaN or -inf in h: {h.tolist()}')
        parts = tuple(self.parts) or ((self.name, G.shape[0]),)
        if sum(rows for _, rows in parts) != G.shape[0]:
            raise ShapeError(f'constraint {self.name!r}: its parts {parts} do not add up to its {G.shape[0]} rows')
        object.__setattr__(self, 'G', G)
        object.__setattr__(self, 'h', h)
        object.__setattr__(self, 'parts', parts)

    @classmethod
    def _checked(cls, G: np.ndarray, h: np.ndarray, name: str, parts: tuple[tuple[str, int], ...]) -> Constraint:
        """A constraint of rows taken from constraints already checked (stacked, selected)."""
        out = object.__new__(cls)
        for key, value in (('G', G), ('h', h), ('name', name), ('parts', parts)):
            object.__setattr__(out, key, value)
        return out

    @property
    def n(self) -> int:
        """The command's entries."""
        return self.G.shape[1]

    def __len__(self) -> int:
        return self.h.size

    @classmethod
    def empty(cls, n: int, name: str = 'constraint') -> Constraint:
        """No rows on a command of ``n`` entries."""
        return cls._checked(np.zeros((0, n)), np.zeros(0), name, ((name, 0),))

    @classmethod
    def from_lower(cls, rows: ArrayLike, bound: ArrayLike, name: str = 'constraint') -> Constraint:
        """Rows ``rows x ≥ bound``, as ``−rows x ≤ −bound``."""
        return cls(-np.asarray(rows, dtype=float), -np.asarray(bound, dtype=float), name)

    @classmethod
    def stack(cls, constraints: Iterable[Constraint], n: int, name: str = 'stack') -> Constraint:
        """``constraints`` one after the other, as one constraint on a command of ``n`` entries;
        :attr:`parts` keeps each one's name and rows (an empty one leaves no part).

        Raises:
            ShapeError: a constraint on another number of entries than ``n``.
        """
        constraints = list(constraints)
        for c in constraints:
            if c.n != n:
                raise ShapeError(f'constraint {c.name!r} is on {c.n} entries, the stack on {n}')
        parts = _merged(part for c in constraints for part in c.parts)
        if not parts:
            return cls.empty(n, name)
        filled = [c for c in constraints if len(c)]
        if len(filled) == 1:
            return cls._checked(filled[0].G, filled[0].h, name, parts)
        return cls._checked(np.vstack([c.G for c in filled]), np.concatenate([c.h for c in filled]), name, parts)

    def select(self, keep: ArrayLike) -> Constraint:
        """The rows where the boolean array ``keep`` (shape (m,)) is true, parts kept."""
        keep = np.asarray(keep, dtype=bool)
        if keep.shape != (len(self),):
            raise ShapeError(f'constraint {self.name!r}: keep must have shape ({len(self)},), got {keep.shape}')
        kept = np.bincount(self._part_of_rows()[keep], minlength=len(self.parts))
        parts = _merged((name, int(rows)) for (name, _), rows in zip(self.parts, kept))
        return Constraint._checked(self.G[keep], self.h[keep], self.name, parts or ((self.name, 0),))

    def residual(self, x: ArrayLike) -> np.ndarray:
        """``G x − h`` (≤ 0 where a row is met). Shape (m,)."""
        return self.G @ np.asarray(x, dtype=float) - self.h

    def violated(self, x: ArrayLike, tolerance: float = TOLERANCE) -> np.ndarray:
        """Which rows ``x`` breaks by more than ``tolerance``. Shape (m,), boolean."""
        return self.residual(x) > tolerance

    def binding(self, x: ArrayLike, tolerance: float = 1e-6) -> dict[str, int]:
        """How many rows of each part ``x`` meets at equality or breaks. A row binds when ``x``
        is within ``tolerance`` of its boundary or beyond it, measured in the command's units
        (its residual over the norm of its ``G`` row); a row on no entry (``G`` within
        :data:`TOLERANCE` of zero, round-off of a pair no entry moves) never binds."""
        norms = np.sqrt(np.einsum('ij,ij->i', self.G, self.G))
        return self.per_part(np.flatnonzero((norms > TOLERANCE) & (self.residual(x) >= -tolerance * norms)))

    def per_part(self, rows: ArrayLike) -> dict[str, int]:
        """How many of the rows ``rows`` (indices, each once) each part holds."""
        held = np.bincount(self._part_of_rows()[np.asarray(rows, dtype=int)], minlength=len(self.parts))
        out = {name: 0 for name, _ in self.parts}
        for (name, _), count in zip(self.parts, held.tolist()):
            out[name] += count
        return out

    def _part_of_rows(self) -> np.ndarray:
        """The index into :attr:`parts` of each row's part. Shape (m,)."""
        return np.repeat(np.arange(len(self.parts)), [rows for _, rows in self.parts])


def _merged(parts) -> tuple[tuple[str, int], ...]:
    """``parts`` without the empty ones, neighbours of one name merged."""
    out: list[tuple[str, int]] = []
    for name, rows in parts:
        if not rows:
            continue
        if out and out[-1][0] == name:
            out[-1] = (name, out[-1][1] + rows)
        else:
            out.append((name, rows))
    return tuple(out)


@dataclass(frozen=True)
class Box:
    """Bounds ``lower ≤ x ≤ upper`` on a command (a period's box,
    :meth:`~wmm_control.resolvers.limits.CommandLimits.box`).

    Raises:
        ShapeError: ``lower`` and ``upper`` not vectors of one shape.
        NonFiniteError: a NaN bound.
        ValueError: ``lower`` above ``upper`` somewhere.
    """

    lower: np.ndarray
    upper: np.ndarray

    def __post_init__(self):
        lower, upper = np.asarray(self.lower, dtype=float), np.asarray(self.upper, dtype=float)
        if lower.ndim != 1 or lower.shape != upper.shape:
            raise ShapeError(f'box: lower and upper must be vectors of one shape, got {lower.shape} and {upper.shape}')
        if not (lower <= upper).all():  # NaN compares false too
            if np.isnan(lower).any() or np.isnan(upper).any():
                raise NonFiniteError(f'box: NaN bounds: {lower.tolist()}, {upper.tolist()}')
            raise ValueError(f'box: lower above upper at entries {np.flatnonzero(lower > upper).tolist()}')
        object.__setattr__(self, 'lower', lower)
        object.__setattr__(self, 'upper', upper)

    @property
    def n(self) -> int:
        return self.lower.size

    def clip(self, x: ArrayLike) -> np.ndarray:
        """``x`` clipped into the box."""
        return np.clip(np.asarray(x, dtype=float), self.lower, self.upper)

    def hold(self, index: slice, value: ArrayLike) -> Box:
        """The box with entries ``index`` held at ``value``."""
        lower, upper = self.lower.copy(), self.upper.copy()
        lower[index] = upper[index] = value
        return Box(lower, upper)

    def greatest(self, G: np.ndarray) -> np.ndarray:
        """The greatest value of each row of ``G x`` over the box (inf where it is unbounded):
        a row ``G x ≤ h`` with ``greatest ≤ h`` holds all over the box."""
        if np.isfinite(self.lower).all() and np.isfinite(self.upper).all():
            return np.maximum(G * self.lower, G * self.upper).sum(axis=1)
        with np.errstate(invalid='ignore'):  # 0 × inf: an entry the row does not involve adds nothing
            values = np.maximum(G * self.lower, G * self.upper)
        return np.nan_to_num(values, nan=0.0, posinf=np.inf, neginf=-np.inf).sum(axis=1)

    def free(self) -> np.ndarray:
        """The entries the box leaves room on (lower < upper). Boolean, shape (n,)."""
        return self.upper > self.lower


class Nearest(NamedTuple):
    """What :func:`nearest` answers.

    Attributes:
        command: the command, within the box. Shape (n,).
        relaxed: the slack was needed (no command in the box meets every row).
        multipliers: each row's Lagrange multiplier (≥ 0; for the problem with slack, the
            rows' own): above zero where the row shapes the answer (without it the answer
            would differ), zero where it does not. Shape (m,).
    """

    command: np.ndarray
    relaxed: bool
    multipliers: np.ndarray


def nearest(target: ArrayLike, metric: ArrayLike, constraint: Constraint, box: Box) -> Nearest:
    """The command nearest ``target`` in the metric ``metric``, under ``constraint`` and within
    ``box``:

        min ½ (x − x₀)ᵀ H (x − x₀)   subject to   G x ≤ h,   lower ≤ x ≤ upper,

    one QP through DAQP (``daqp.solve``; ``H`` positive definite; the box as its simple bounds).
    On 10 variables and 40 rows it takes tens of microseconds, a few less than through
    :mod:`qpsolvers`, which has no way to pass DAQP's soft rows. Where no command in the box
    meets every row, the same solver takes the problem again with every row soft (DAQP's
    ``sense`` flag): a slack ``s ≥ 0`` per row (``G x ≤ h + s``) at :data:`SLACK_COST` per unit
    (:data:`MEETABLE_COST` times that for a row some command in the box meets on its own) and
    :data:`SLACK_WEIGHT` quadratic, the box kept hard: the rows met as far as the box allows,
    those the box could keep first, in one problem over ``x`` alone. Where that fails too (an
    empty box, a failed solver), the point of the box nearest zero: stop as hard as the box
    allows (no row's multiplier then).

    Returns:
        :class:`Nearest`: ``(command, relaxed, multipliers)``.
    """
    x0 = np.asarray(target, dtype=float)
    H = np.asarray(metric, dtype=float)
    n, m = x0.size, len(constraint)
    if constraint.n != n or box.n != n or H.shape != (n, n):
        raise ShapeError(
            f'nearest: a target of {n} entries with a constraint on {constraint.n}, a box of {box.n} '
            f'and a metric of shape {H.shape}'
        )
    linear = -H @ x0
    # the box first, as DAQP's simple bounds, then the rows (no lower bound)
    upper = np.concatenate((box.upper, constraint.h))
    lower = np.concatenate((box.lower, np.full(m, -np.inf)))
    sense = np.zeros(n + m, dtype=np.intc)
    x, _, flag, info = daqp.solve(H, linear, constraint.G, upper, lower, sense)
    if flag > 0 and np.all(np.isfinite(x)):
        return Nearest(box.clip(x), False, _multipliers(info['lam'][n:]))
    sense[n:] = _SOFT
    # a row some command in the box meets (its least value over the box within its bound)
    meetable = -box.greatest(-constraint.G) <= constraint.h + TOLERANCE
    cost = np.where(meetable, MEETABLE_COST * SLACK_COST, SLACK_COST)
    model = daqp.Model()
    model.setup(H, linear, constraint.G, upper, lower, sense)
    model.soft_weights(rho_u=np.full(n + m, 1.0 / SLACK_WEIGHT), w_u=np.concatenate((np.full(n, SLACK_COST), cost)))
    x, _, flag, info = model.solve()
    if not (flag > 0 and np.all(np.isfinite(x))):
        return Nearest(box.clip(np.zeros(n)), True, np.zeros(m))
    x = box.clip(x)
    # a broken row's multiplier is its slack's price, its cost + SLACK_WEIGHT s (the
    # stationarity of its penalty); DAQP may leave it out for a row whose slack no command in
    # the box changes
    broken = np.maximum(constraint.residual(x), 0.0)
    multipliers = _multipliers(info['lam'][n:])
    return Nearest(x, True, np.where(broken > TOLERANCE, cost + SLACK_WEIGHT * broken, multipliers))


def _multipliers(z) -> np.ndarray:
    """The rows' multipliers of the solver's answer (zero where it gives a NaN)."""
    return np.nan_to_num(np.maximum(np.asarray(z, dtype=float), 0.0))
