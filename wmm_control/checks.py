"""Input validation helpers shared by the core (shape and finiteness checks, the age of an input)."""

import math

import numpy as np
from numpy.typing import ArrayLike

from wmm_control.errors import NonFiniteError, ShapeError

__all__ = ['as_vector', 'as_finite_vector', 'Freshness', 'PLAUSIBLE_FACTOR']

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
