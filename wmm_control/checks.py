"""Input validation helpers shared by the core (shape and finiteness checks)."""

import numpy as np

from wmm_control.errors import NonFiniteError, ShapeError

__all__ = ['as_vector', 'as_finite_vector']


def as_vector(value, size, name):
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


def as_finite_vector(value, size, name):
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

