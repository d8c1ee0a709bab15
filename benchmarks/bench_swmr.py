"""Per-cycle cost of SwmrController.step (robot A geometry, Table I period).

Runs ~5000 cycles of a varying reference (arcs, translations in all directions, spins, arc
switches through infinity, reversals, stops) and prints:

- the median and p99 wall time of ``step``, in µs;
- the OSQP solve, counted only over the cycles that call OSQP, and how many do;
- the status counts (``unconstrained``: ICR_ref lies in every wedge, OSQP not called;
  ``elastic``: the wedges had no common point; ``not_solved``: steering held at rest);
- where a cycle's time goes: the median of each part of ``step`` per cycle;
- the floor: a stripped cycle that does only the work a cycle calling OSQP cannot skip (the
  QP data, one OSQP update and solve, and the wheel outputs), replayed over the cycles that
  call OSQP, with the median of each part.

Side by side, in the same run: one differential-IK step of pink (``pin-pink`` with the
quadprog solver, a frame task on the end effector and a posture task) on robot A's
10-DOF model, the kind of per-cycle work a QP-based whole-body IK does. pink is installed
for the benchmark only (``bash scripts/dev.sh bench`` installs it); without it that part
is skipped with a message.

    python benchmarks/bench_swmr.py [--cycles 5000]
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a source checkout
sys.path.insert(0, str(Path(__file__).resolve().parent))  # the benchmarks' shared code

from shared import bench_pink  # noqa: E402
from wmm_control.base import OsqpIcrSolver, SteerableGeometry, SwmrController, SwmrParams  # noqa: E402
from wmm_control.base.icr import wedge_rows  # noqa: E402
from wmm_control.robot_config import load_robot  # noqa: E402

PARTS = ('_resync', '_icr_qp', 'solver', '_steer', '_drive', '_feasible_twist', '_commit')
"""The parts of ``step`` timed separately (``solver``: the OSQP call, inside the steering)."""


def reference(k, dt):
    """A reference twist (vx, vy, ω) [m/s, m/s, rad/s] that changes character every 2 s."""
    t = k * dt
    phase = int(t // 2.0) % 8
    s = np.sin(0.7 * t)
    if phase == 0:
        return np.array([0.5, 0.0, 0.25 * s])  # arcs left/right
    if phase == 1:
        return np.array([0.4 * np.cos(t), 0.4 * np.sin(t), 0.0])  # rotating translation
    if phase == 2:
        return np.array([0.0, 0.0, 0.6 * s])  # spin
    if phase == 3:
        return np.array([-0.4, 0.2, 0.3])  # reversal-ish arc
    if phase == 4:
        return np.zeros(3)  # stop
    if phase == 5:
        return np.array([0.3, -0.3, -0.4 * s])
    if phase == 6:
        return np.array([0.3 * s, -0.24 * 0.3, 0.3])  # ICR sweeping past the hips
    return np.array([0.6, 0.1, 0.0])


def controller():
    robot = load_robot('steerable')
    return SwmrController(SteerableGeometry.from_config(robot.base), SwmrParams.from_robot_config(robot))


def time_steps(ctrl, cycles):
    """Step times [µs], OSQP solve times [µs] of the cycles that call it, status counts."""
    dt = ctrl.params.dt
    for k in range(50):  # warm-up (imports, caches)
        ctrl.step(reference(k, dt))
    ctrl.reset(np.zeros(ctrl.geometry.n_wheels))
    step_us, solve_us, statuses = [], [], {}
    for k in range(cycles):
        ref = reference(k, dt)
        t0 = time.perf_counter()
        out = ctrl.step(ref)
        step_us.append((time.perf_counter() - t0) * 1e6)
        if out.solve_time_s > 0:
            solve_us.append(out.solve_time_s * 1e6)
        statuses[out.qp_status] = statuses.get(out.qp_status, 0) + 1
    return np.array(step_us), np.array(solve_us), statuses


def time_parts(ctrl, cycles):
    """Median time [µs] per cycle of each part of ``step`` (wrapped with timers)."""
    spent = {name: 0.0 for name in PARTS}
    per_cycle = {name: [] for name in PARTS}

    def timed(name, fn):
        def wrapper(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                spent[name] += time.perf_counter() - t0

        return wrapper

    for name in PARTS:
        setattr(ctrl, name, timed(name, getattr(ctrl, name)))
    dt = ctrl.params.dt
    ctrl.reset(np.zeros(ctrl.geometry.n_wheels))
    for k in range(cycles):
        for name in PARTS:
            spent[name] = 0.0
        ctrl.step(reference(k, dt))
        for name in PARTS:
            per_cycle[name].append(spent[name] * 1e6)
    return {name: (np.median(v), np.mean(v)) for name, v in per_cycle.items()}


def record_qps(ctrl, cycles):
    """The QPs that ``ctrl`` hands OSQP over the reference, each with the steer angles it started from."""
    qps = []
    solve = ctrl.solver

    def recording(problem):
        qps.append((problem, ctrl.beta, ctrl.twist))
        return solve(problem)

    ctrl.solver = recording
    ctrl.reset(np.zeros(ctrl.geometry.n_wheels))
    for k in range(cycles):
        ctrl.step(reference(k, ctrl.params.dt))
    ctrl.solver = solve
    return qps


def time_floor(cycles):
    """Median time [µs] of each part of a stripped cycle, over the cycles that call OSQP.

    Parts: ``qp data`` (the 2N wedge rows of the period's steer-angle intervals and OSQP's
    arrays of them), ``osqp`` (one update of q, l, u and A's values and one solve, at the
    controller's settings, warm-started as in the controller), and ``wheel outputs`` (the
    steer angles of ICR_next and the drive rates for the twist). The rest of a cycle (ICR*,
    route, ICR_ref, the wedge sides, the rate clip, the acceleration and drive limits, the
    executed twist) is left out.
    """
    ctrl = controller()
    qps = record_qps(ctrl, cycles)
    solver = OsqpIcrSolver(ctrl.n_rows, ctrl.params.eps, ctrl.params.max_iter)
    g, dt = ctrl.geometry, ctrl.params.dt
    row_maps = np.repeat(g.hip_velocity_map(ctrl.params.icr_scale), 2, axis=0)
    parts = {'qp data': [], 'osqp': [], 'wheel outputs': [], 'total': []}
    for problem, beta, twist in qps:
        signs = np.column_stack((problem.sides, -problem.sides)).ravel()
        t0 = time.perf_counter()
        headings = np.column_stack((beta + dt * problem.rate_lower, beta + dt * problem.rate_upper)).ravel()
        problem.rows, problem.lower = wedge_rows(headings, signs, row_maps, problem.icr_curr.z, problem.basis)
        a, lb, ub = problem.A, problem.l, problem.u
        t1 = time.perf_counter()
        y, _ = solver._run(solver._osqp, -problem.x_ref, a, lb, ub)
        t2 = time.perf_counter()
        beta_new = g.steer_angles_for_icr(problem.icr_of(y), near=beta)
        g.drive_rates(g.rolling_rows(beta_new), (beta_new - beta) / dt, twist)
        t3 = time.perf_counter()
        for name, t in (('qp data', t1 - t0), ('osqp', t2 - t1), ('wheel outputs', t3 - t2), ('total', t3 - t0)):
            parts[name].append(t * 1e6)
    return {name: float(np.median(v)) for name, v in parts.items()}, len(qps)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--cycles', type=int, default=5000)
    args = parser.parse_args()
    ctrl = controller()
    step_us, solve_us, statuses = time_steps(ctrl, args.cycles)
    med, p99 = np.median(step_us), np.percentile(step_us, 99)
    print(f'SwmrController.step over {args.cycles} cycles (dt = {ctrl.params.dt} s):')
    print(f'  step   median {med:7.1f} us   p99 {p99:7.1f} us   max {step_us.max():7.1f} us')
    print(
        f'  OSQP   median {np.median(solve_us):7.1f} us   p99 {np.percentile(solve_us, 99):7.1f} us   '
        f'over the {len(solve_us)} cycles that call it ({len(solve_us) / args.cycles:.0%})'
    )
    print('  qp status counts:', ', '.join(f'{k}: {v}' for k, v in sorted(statuses.items())))
    parts = time_parts(controller(), args.cycles)
    print(
        '  per cycle, median / mean [us]: '
        + ', '.join(f'{name.strip("_")} {m:.1f} / {a:.1f}' for name, (m, a) in parts.items())
    )
    floor, n_qp = time_floor(args.cycles)
    print(
        f'  floor, a stripped cycle over the {n_qp} OSQP calls, median [us]: '
        + ', '.join(f'{name} {m:.1f}' for name, m in floor.items())
    )
    pink_us = bench_pink(args.cycles)
    if pink_us is None:
        print('pink not installed (pip install pin-pink quadprog): comparison skipped')
        return
    pmed = np.median(pink_us)
    print(f'pink solve_ik (quadprog), robot A: median {pmed:7.1f} us   p99 {np.percentile(pink_us, 99):7.1f} us')
    print(
        f'  ratio: our median / pink median = {med / pmed:.2f} (target <= 0.5); '
        f'our p99 / our median = {p99 / med:.2f} (target <= 3)'
    )


if __name__ == '__main__':
    main()
