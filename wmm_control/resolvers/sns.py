"""Saturation in the null space (SNS, Flacco et al. 2012): one loop for both levels.

A task ``J x = t − o`` is solved through a generalised inverse ``P`` of ``J`` over the joints
still active; a joint whose entry would pass its bound is taken out of the active set and held
at that bound, and the task is shared again by the joints still active:
``x = x_N + P (t − o − J x_N)``, with ``x_N`` the held entries.

* Acceleration level, Xing eq (9): ``q̈ = q̈_N + (J S)⁺ (α ẍ − J̇q̇ − J q̈_N)``
  (:func:`sns_accelerations`): the joint that binds first is held, one per round, and when no
  active set satisfies every bound the task is scaled by the largest ``α ∈ [0, 1]`` found
  along the way (the task scaling of Xing's Fig 4).
* Velocity level (the ``hold_joint_limits`` and ``arm_takeover`` options of the pose-servo
  resolvers): ``P`` is the weighted damped pseudo-inverse of Sorour eq (9), every entry past
  its bound is held in the same round, and the task is not scaled (the command limits scale
  the whole command afterwards).
"""

from collections.abc import Callable
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from wmm_control.geometry import largest_step

__all__ = ['SnsResult', 'full_row_rank_pinv', 'saturate_in_null_space', 'sns_accelerations']

_TOL = 1e-9


class SnsResult(NamedTuple):
    """What :func:`saturate_in_null_space` found.

    Attributes:
        qdd: the solution x (at acceleration level q̈). Shape (n,).
        alpha: the task scale α ∈ [0, 1] (1 without task scaling).
        active: the active set S used (bool). Shape (n,).
        saturated: joints taken out and held at a bound (bool). Shape (n,).
        pinv: the inverse P over the active columns, shape (|S|, r), for the null-space
            projector of Xing eqs (10)–(11); None when no active set had one.
    """

    qdd: np.ndarray
    alpha: float
    active: np.ndarray
    saturated: np.ndarray
    pinv: object


def full_row_rank_pinv(a: np.ndarray, rcond: float) -> np.ndarray | None:
    """``a⁺`` when ``a`` (r, k) has full row rank, else None.

    Full row rank: r singular values, the smallest above ``rcond`` times the largest. One
    ``numpy.linalg.lstsq`` call gives both: the minimum-norm least-squares solution of
    ``a X = I`` is ``a⁺``, with the singular values below ``rcond`` times the largest cut, as
    ``numpy.linalg.pinv(a, rcond)`` cuts them, and the rank they leave.
    """
    pinv, _, rank, _ = np.linalg.lstsq(a, np.eye(a.shape[0]), rcond=rcond)  # a⁺ I, and the rank
    return pinv if rank == a.shape[0] else None


def saturate_in_null_space(
    inverse: Callable[[np.ndarray], np.ndarray | None],
    jac: np.ndarray,
    task: np.ndarray,
    offset: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    active: ArrayLike,
    held: np.ndarray,
    one_at_a_time: bool = True,
    scale: bool = True,
) -> SnsResult:
    """Solve ``J x = task − offset`` within ``lower ≤ x ≤ upper`` by saturation in the null space.

    Args:
        inverse: ``inverse(cols)`` gives the generalised inverse of ``J`` over the active
            columns ``cols`` (int indices), shape (|cols|, r), or None when that set cannot do
            the task (e.g. ``J S`` loses rank).
        jac: J. Shape (r, n).
        task: the task vector (ẍ, or ṗ_ref), the part that scaling shrinks. Shape (r,).
        offset: the part that is not scaled (J̇q̇, or 0). Shape (r,).
        lower, upper: bounds of x (±inf where there are none). Shape (n,).
        active: entries that may take part; the others stay at ``held``. Shape (n,).
        held: the values of the entries outside ``active``. Shape (n,).
        one_at_a_time: hold only the entry that binds first in a round (Flacco's SNS); False:
            every entry past its bound.
        scale: when no active set keeps every bound, return the solution with the task scaled
            by the largest α found, clipped into the bounds; False: the last round's solution.

    Returns:
        :class:`SnsResult`.
    """
    n = jac.shape[1]
    act = np.asarray(active, dtype=bool).copy()
    x_n = np.where(act, 0.0, held)
    saturated = np.zeros(n, dtype=bool)
    best = last = None
    for _ in range(n + 1):
        cols = np.flatnonzero(act)
        if cols.size == 0:
            break
        inv = inverse(cols)
        if inv is None:
            break  # this set cannot do the task
        a = x_n.copy()
        b = np.zeros(n)
        a[cols] += inv @ (-offset - jac @ x_n)
        b[cols] = inv @ task
        x = a + b
        over = act & ((x > upper + _TOL) | (x < lower - _TOL))
        if not over.any():
            return SnsResult(x, 1.0, act, saturated, inv)
        if scale or one_at_a_time:
            s, per = largest_step(a, b, lower, upper, act)
            if scale and (best is None or s > best.alpha):
                best = SnsResult(np.clip(a + s * b, lower, upper), s, act.copy(), saturated.copy(), inv)
            if one_at_a_time:
                first = np.argmin(np.where(over, per, np.inf))  # the entry that binds first
                over = np.zeros(n, dtype=bool)
                over[first] = True
        if not scale:
            last = SnsResult(x, 1.0, act.copy(), saturated.copy(), inv)
        act &= ~over
        saturated |= over
        x_n[over] = np.clip(x[over], lower[over], upper[over])
    if best is not None:
        return best
    if last is not None:
        return last
    return SnsResult(np.clip(x_n, lower, upper), 0.0, act, saturated, None)


def sns_accelerations(
    jac: np.ndarray,
    xdd: np.ndarray,
    drift: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    active: ArrayLike,
    held: np.ndarray,
    rcond: float = 1e-6,
) -> SnsResult:
    """Xing eq (9) by saturation in the null space.

    Args:
        jac: task Jacobian J. Shape (r, n).
        xdd: commanded task acceleration ẍ. Shape (r,).
        drift: J̇q̇. Shape (r,).
        lower, upper: this period's joint acceleration bounds (eqs 6–8). Shape (n,).
        active: joints that may take part (the base's entries False keep it out). Shape (n,).
        held: accelerations of the joints outside ``active`` (e.g. the base braking, eq 15).
            Shape (n,).
        rcond: relative singular-value cut-off of the pseudo-inverses.

    Returns:
        :class:`SnsResult`.
    """
    return saturate_in_null_space(
        lambda cols: full_row_rank_pinv(jac[:, cols], rcond), jac, xdd, drift, lower, upper, active, held
    )
