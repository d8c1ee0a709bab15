"""Saturation in the null space (Flacco et al. 2012) at acceleration level: Xing eq (9).

``q̈ = q̈_N + (J S)⁺ (α ẍ − J̇q̇ − J q̈_N)``: joints are taken out of the active set ``S`` one by
one, each held at the bound it would pass (its entry of ``q̈_N``), and the task is shared
by the joints still active. When no active set satisfies every bound, the task is scaled by
the largest ``α ∈ [0, 1]`` found along the way (the task scaling of Xing's Fig 4).
"""

import numpy as np

__all__ = ['sns_accelerations', 'task_scale']

_TOL = 1e-9


def task_scale(start, step, lower, upper, mask):
    """Largest ``s ∈ [0, 1]`` with ``lower ≤ start + s·step ≤ upper`` on the entries of ``mask``.

    Returns:
        (s, per_entry): ``per_entry`` is each masked entry's own largest s (inf where it does
        not bind, 0 where ``start`` is already out of bounds; inf outside the mask).
    """
    with np.errstate(divide='ignore', invalid='ignore'):
        s_up = np.where(step > 0, (upper - start) / step, np.inf)
        s_dn = np.where(step < 0, (lower - start) / step, np.inf)
    per = np.minimum(s_up, s_dn)
    per = np.where((start > upper + _TOL) | (start < lower - _TOL), 0.0, np.maximum(per, 0.0))
    per = np.where(mask, per, np.inf)
    return float(min(1.0, np.min(per))), per


def sns_accelerations(jac, xdd, drift, lower, upper, active, held, rcond=1e-6):
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
        (q̈ (n,), α, active set used (n,) bool, saturated joints (n,) bool).
    """
    n, r = jac.shape[1], jac.shape[0]
    act = np.asarray(active, dtype=bool).copy()
    q_n = np.where(act, 0.0, held)
    saturated = np.zeros(n, dtype=bool)
    best = None
    for _ in range(n + 1):
        cols = np.flatnonzero(act)
        if cols.size == 0:
            break
        jc = jac[:, cols]
        sv = np.linalg.svd(jc, compute_uv=False)
        if sv.size < r or sv[r - 1] <= rcond * sv[0]:
            break                          # rank(J S) < r: this set cannot do the task
        jp = np.linalg.pinv(jc, rcond=rcond)
        a = q_n.copy()
        a[cols] += jp @ (-drift - jac @ q_n)
        b = np.zeros(n)
        b[cols] = jp @ xdd
        q = a + b
        over = act & ((q > upper + _TOL) | (q < lower - _TOL))
        if not np.any(over):
            return q, 1.0, act, saturated
        s, per = task_scale(a, b, lower, upper, act)
        if best is None or s > best[1]:
            best = (np.clip(a + s * b, lower, upper), s, act.copy(), saturated.copy())
        worst = int(np.argmin(np.where(over, per, np.inf)))
        act[worst] = False
        saturated[worst] = True
        q_n[worst] = upper[worst] if q[worst] > upper[worst] else lower[worst]
    if best is None:
        return np.clip(q_n, lower, upper), 0.0, act, saturated
    return best
