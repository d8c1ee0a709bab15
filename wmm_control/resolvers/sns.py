"""Saturation in the null space (Flacco et al. 2012) at acceleration level: Xing eq (9).

``q̈ = q̈_N + (J S)⁺ (α ẍ − J̇q̇ − J q̈_N)``: joints are taken out of the active set ``S`` one by
one, each held at the bound it would pass (its entry of ``q̈_N``), and the task is shared
by the joints still active. When no active set satisfies every bound, the task is scaled by
the largest ``α ∈ [0, 1]`` found along the way (the task scaling of Xing's Fig 4).
"""

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from wmm_control.geometry import largest_step

__all__ = ['SnsResult', 'full_row_rank_pinv', 'sns_accelerations']

_TOL = 1e-9


class SnsResult(NamedTuple):
    """What :func:`sns_accelerations` found.

    Attributes:
        qdd: joint accelerations q̈. Shape (n,).
        alpha: the task scale α ∈ [0, 1].
        active: the active set S used (bool). Shape (n,).
        saturated: joints taken out and held at a bound (bool). Shape (n,).
        pinv: (J S)⁺ over the active columns, shape (|S|, r), for the null-space projector of
            eqs (10)–(11); None when no active set had full row rank.
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
    n = jac.shape[1]
    act = np.asarray(active, dtype=bool).copy()
    q_n = np.where(act, 0.0, held)
    saturated = np.zeros(n, dtype=bool)
    best = None
    for _ in range(n + 1):
        cols = np.flatnonzero(act)
        if cols.size == 0:
            break
        jp = full_row_rank_pinv(jac[:, cols], rcond)
        if jp is None:
            break  # rank(J S) < r: this set cannot do the task
        a = q_n.copy()
        a[cols] += jp @ (-drift - jac @ q_n)
        b = np.zeros(n)
        b[cols] = jp @ xdd
        q = a + b
        over = act & ((q > upper + _TOL) | (q < lower - _TOL))
        if not np.any(over):
            return SnsResult(q, 1.0, act, saturated, jp)
        s, per = largest_step(a, b, lower, upper, act)
        if best is None or s > best.alpha:
            best = SnsResult(np.clip(a + s * b, lower, upper), s, act.copy(), saturated.copy(), jp)
        worst = int(np.argmin(np.where(over, per, np.inf)))
        act[worst] = False
        saturated[worst] = True
        q_n[worst] = upper[worst] if q[worst] > upper[worst] else lower[worst]
    if best is None:
        return SnsResult(np.clip(q_n, lower, upper), 0.0, act, saturated, None)
    return best
