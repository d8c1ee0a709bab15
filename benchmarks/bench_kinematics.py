"""Per-cycle cost of the kinematics core, per robot. Prints median and p99 in µs.

Figures per robot:
* ``pose + J_a + J_mm``: update(base, q) then the base-frame pose, J_a and J_mm —
  what the task-sharing resolver needs each cycle;
* ``full update``: update with rates, then world pose, J_a, J_mm, J and J̇q̇;
* ``∇H + ∇²H``: after an update, the gradient then the Hessian of det(J_m J_mᵀ) over the
  arm joints (what the acceleration-level planner asks for each cycle), position rows;
  ``∇H + ∇²H, full``: the same over all six rows.
"""

import time

import numpy as np

from wmm_control.kinematics import KinematicModel
from wmm_control.kinematics.tasks import ManipulabilityTask

N = 5000


def percentiles(samples):
    us = np.asarray(samples) * 1e6
    return np.median(us), np.percentile(us, 99)


def bench(model, full, rng):
    cfg = model.config
    lo = np.maximum(cfg.arm.position_lower, -np.pi)
    hi = np.minimum(cfg.arm.position_upper, np.pi)
    states = [(rng.uniform(-1, 1, 3), rng.uniform(lo, hi), rng.normal(size=3), rng.normal(size=7)) for _ in range(N)]
    times = []
    for base, q, vb, dq in states:
        t0 = time.perf_counter()
        if full:
            model.update(base, q, base_rate=vb, dq_arm=dq)
            model.ee_placement_world()
            model.ee_pose_base()
            model.arm_jacobian_base()
            model.jmm()
            model.jacobian_world()
            model.jdot_qdot()
        else:
            model.update(base, q)
            model.ee_pose_base()
            model.arm_jacobian_base()
            model.jmm()
        times.append(time.perf_counter() - t0)
    return percentiles(times[100:])


def bench_manipulability(model, rows, rng):
    times = []
    task = ManipulabilityTask(model, rows)
    for _ in range(N):
        model.update(rng.uniform(-1, 1, 3), rng.uniform(-2, 2, 7))
        t0 = time.perf_counter()
        task.gradient()
        task.hessian()
        times.append(time.perf_counter() - t0)
    return percentiles(times[100:])


def main():
    rng = np.random.default_rng(0)
    print(f'{"robot":<10} {"what":<20} {"median µs":>10} {"p99 µs":>8}')
    for robot in ('steerable', 'mecanum'):
        model = KinematicModel(robot)
        for full, label in ((False, 'pose + J_a + J_mm'), (True, 'full update')):
            med, p99 = bench(model, full, rng)
            print(f'{robot:<10} {label:<20} {med:>10.1f} {p99:>8.1f}')
        for rows, label in (('position', '∇H + ∇²H'), ('full', '∇H + ∇²H, full')):
            med, p99 = bench_manipulability(model, rows, rng)
            print(f'{robot:<10} {label:<20} {med:>10.1f} {p99:>8.1f}')


if __name__ == '__main__':
    main()
