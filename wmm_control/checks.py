"""Input validation helpers shared by the core (shape and finiteness checks, the age of an input)."""

import math

import numpy as np
from numpy.typing import ArrayLike

from wmm_control.errors import NonFiniteError, ShapeError

__all__ = ['as_vector', 'as_finite_vector', 'Freshness', 'JointCheck', 'PLAUSIBLE_FACTOR']

#: A measured rate or twist beyond this many times its limit is taken for a glitch, not a
#: measurement (joint states, odometry, the base's feasible twist).
PLAUSIBLE_FACTOR = 10.0


def as_vector(value: ArrayLike, size: int | None, name: str) -> np.ndarray:
    """Return ``value`` as a float64 vector of length ``size`` (any length when None).

    Raises:
        ShapeError: if ``value`` does not hold exactly ``size`` numbers (a 1-D list of them).
    """
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ShapeError(f'{name}: expected {size} numbers, got {value!r}') from exc
    if arr.ndim != 1 or (size is not None and arr.shape != (size,)):
        want = f'({size},)' if size is not None else 'a 1-D vector'
        raise ShapeError(f'{name}: expected shape {want}, got {arr.shape}')
    return arr


def as_finite_vector(value: ArrayLike, size: int | None, name: str) -> np.ndarray:
    """Like :func:`as_vector`, and also reject NaN and infinity.

    Raises:
        ShapeError: wrong length.
        NonFiniteError: any entry is NaN or infinite.
    """
    arr = as_vector(value, size, name)
    if not np.isfinite(arr).all():
        bad = np.flatnonzero(~np.isfinite(arr)).tolist()
        raise NonFiniteError(f'{name}: non-finite entries at indices {bad}: {arr.tolist()}')
    return arr


class Freshness:
    """Age of the last received message, judged by the receiver's clock at receipt.

    A message's own header stamp is never used: a sender with a skewed or paused clock
    cannot make stale data look fresh.
    """

    def __init__(self, timeout: float) -> None:
        self.timeout = float(timeout)
        self._last: float | None = None

    def mark(self, now: float) -> None:
        """Record a receipt at time ``now`` [s]."""
        self._last = now

    def reset(self) -> None:
        self._last = None

    def age(self, now: float) -> float:
        """Seconds since the last receipt; infinity before the first one."""
        return math.inf if self._last is None else now - self._last

    def fresh(self, now: float) -> bool:
        """True when a message arrived within the timeout (and the clock did not jump back)."""
        age = self.age(now)
        return 0.0 <= age <= self.timeout


class JointCheck:
    """The checks of a measured joint state's values, for both engines: a state that fails them
    runs no cycle (the nodes read the joints by name first,
    :class:`~wmm_control.nodes.inputs.JointSelector`).

    Rejected: non-finite positions or rates, rates beyond :data:`PLAUSIBLE_FACTOR` times their
    limits, positions beyond :attr:`MAX_POSITION` or beyond their limits by more than
    :attr:`POSITION_MARGIN`.

    Args:
        joints: the joint names, in the order of the values checked (named in the reasons).
        velocity_limits: optional |q̇| limit per joint (or one for all) [rad/s].
        position_limits: optional ``(lower, upper)`` per joint [rad].
    """

    POSITION_MARGIN = 0.5  # [rad]
    MAX_POSITION = 1e9  # [rad] no joint angle is larger (a wheel at 12 rad/s needs 2.6 years)

    def __init__(
        self,
        joints,
        velocity_limits: ArrayLike | None = None,
        position_limits: tuple[ArrayLike, ArrayLike] | None = None,
    ) -> None:
        self.joints = tuple(joints)
        # every check as one bound per joint, for the usual state that passes them all (NaN
        # fails a comparison): the positions within their limits and ±MAX_POSITION, the rates
        # within PLAUSIBLE_FACTOR times theirs
        n = len(self.joints)
        self._lowest, self._highest = np.full(n, -self.MAX_POSITION), np.full(n, self.MAX_POSITION)
        if position_limits is not None:
            self._lowest = np.maximum(self._lowest, np.asarray(position_limits[0], dtype=float) - self.POSITION_MARGIN)
            self._highest = np.minimum(
                self._highest, np.asarray(position_limits[1], dtype=float) + self.POSITION_MARGIN
            )
        self._fastest = (
            np.full(n, np.finfo(float).max)
            if velocity_limits is None
            else PLAUSIBLE_FACTOR * np.broadcast_to(np.asarray(velocity_limits, dtype=float), n)
        )

    def read(self, q: ArrayLike, dq: ArrayLike | None) -> tuple[np.ndarray, np.ndarray, str] | tuple[None, None, str]:
        """``(positions, rates, '')`` when ``q`` and ``dq`` (None: zero rates, the state has
        none) pass, else ``(None, None, reason)``."""
        q = np.asarray(q, dtype=float)
        dq = np.zeros(len(q)) if dq is None else np.asarray(dq, dtype=float)
        if (
            q.shape == self._lowest.shape
            and dq.shape == q.shape
            and (self._lowest <= q).all()
            and (q <= self._highest).all()
            and (np.abs(dq) <= self._fastest).all()
        ):
            return q, dq, ''
        return None, None, self._reason(q, dq)

    def _reason(self, q: np.ndarray, dq: np.ndarray) -> str:
        """Why ``q`` and ``dq`` fail :meth:`read`'s checks."""
        if q.shape != (len(self.joints),) or dq.shape != q.shape:
            return f'with {q.size} positions and {dq.size} rates for {len(self.joints)} joints'
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(dq))):
            return f'with non-finite values: positions {q.tolist()}, velocities {dq.tolist()}'
        if np.any(np.abs(dq) > self._fastest):
            bad = [self.joints[i] for i in np.flatnonzero(np.abs(dq) > self._fastest)]
            return f'with rates of {bad} beyond {PLAUSIBLE_FACTOR:g} times their limits (a measurement glitch?)'
        if np.any(np.abs(q) > self.MAX_POSITION):
            return f'with positions beyond {self.MAX_POSITION:g} rad: not joint angles'
        bad = [self.joints[i] for i in np.flatnonzero((q < self._lowest) | (q > self._highest))]
        return f'with positions of {bad} more than {self.POSITION_MARGIN} rad beyond their limits'
