"""Cost of the safety stage per cycle on every shipped robot. Prints figures, asserts nothing.

For each robot: the number of checked pairs, then :meth:`SafetyStage.filter` at random arm
configurations within the position limits (a random command of 0.5 rad/s per joint, the
velocity limits as the box, the arm's task Jacobian as the methods pass it), split by whether
the command passed unchanged (distances and the rows of the pairs within the look-ahead
distance) or a QP was solved; median and p99 [µs]. Random configurations are harder than a run's: many of them have the arm folded close
to the body or to itself.

Then the same with the obstacles of ``table_pillar`` and the base in the command (its axes in
its own frame, as ``pinv`` and ``task_sharing`` pass it, within its velocity limits; a
lagging base's measured twist drawn within them too): the base at random poses around the
table and the pillar, those in contact left out. Each obstacle adds a pair per link; a pair
with an obstacle adds the rows of a base that brakes (and, for a lagging base, of its path,
the corners of the box between its measured twist and the reference, and its turn).

Each line ends with the cost of counting the answer's binding limits
(:class:`~wmm_control.resolvers.safety.SafetyCounts`: what a cycle adds for the resolver's
``/diagnostics`` and a run's summary), over the answers a QP gave (the others cost a look at
a field).

    python benchmarks/bench_safety.py [--configurations 300]
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run from a source checkout

from wmm_control.geometry import rotation_z  # noqa: E402
from wmm_control.kinematics import KinematicModel  # noqa: E402
from wmm_control.kinematics.obstacles import load_obstacles  # noqa: E402
from wmm_control.resolvers.safety import SafetyCounts, SafetyStage  # noqa: E402
from wmm_control.robot_config import load_robot, robot_names  # noqa: E402


def _figures(times, digits=0):
    if not times:
        return '—'
    us = np.array(times) * 1e6
    return f'median {np.median(us):6.{digits}f} µs, p99 {np.percentile(us, 99):6.{digits}f} µs ({len(us)} cycles)'


def _counted(counts, out, times):
    """Count the answer ``out`` in ``counts``, timed into ``times`` when a QP gave it (else
    there is nothing to look into)."""
    t0 = time.perf_counter()
    counts.add(out)
    if out.multipliers is not None:
        times.append(time.perf_counter() - t0)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--configurations', type=int, default=300)
    args = parser.parse_args(argv)
    for name in robot_names():
        robot = load_robot(name)
        stage = SafetyStage.for_robot(robot)
        model = KinematicModel(robot)
        arm = robot.arm
        rng = np.random.default_rng(0)
        lower = np.where(np.isfinite(arm.position_lower), arm.position_lower, -np.pi)
        upper = np.where(np.isfinite(arm.position_upper), arm.position_upper, np.pi)
        passed, solved, counting = [], [], []
        counts = SafetyCounts()
        for q in rng.uniform(lower, upper, size=(args.configurations, lower.size)):
            command = 0.5 * rng.normal(size=lower.size)
            model.update(robot.start.base_pose, q)
            jacobian = model.arm_jacobian_base()
            t0 = time.perf_counter()
            out = stage.filter(
                q,
                np.clip(command, -arm.velocity, arm.velocity),
                -arm.velocity,
                arm.velocity,
                base_pose=robot.start.base_pose,
                task_jacobian=jacobian,
            )
            (solved if out.changed else passed).append(time.perf_counter() - t0)
            _counted(counts, out, counting)
        print(
            f'{name:12s} {len(stage.collision.pairs):4d} pairs   passed: {_figures(passed)}   QP: {_figures(solved)}'
            f'   counting: {_figures(counting, 1)}'
        )
    print('with table_pillar, the base in the command:')
    for name in robot_names():
        _with_obstacles(load_robot(name), args.configurations)


def _with_obstacles(robot, count):
    """The stage's cost at ``count`` random base poses around ``table_pillar``'s obstacles."""
    stage = SafetyStage.for_robot(robot, obstacles=load_obstacles('table_pillar'))
    model = KinematicModel(robot)
    arm, axes = robot.arm, list(robot.base.axes)
    limit = np.concatenate((robot.base.velocity[axes], arm.velocity))
    rng = np.random.default_rng(0)
    passed, solved, rows, counting = [], [], [], []
    counts = SafetyCounts()
    while len(passed) + len(solved) < count:
        pose = rng.uniform((0.2, -1.6, -np.pi), (2.8, 1.6, np.pi))
        q = np.array(robot.start.arm)
        if stage.collision.within(q, 0.0, pose)[1] <= 0.0:
            continue  # in contact
        measured = rng.uniform(-1.0, 1.0, 3) * robot.base.velocity
        command = np.clip(rng.uniform(-1.0, 1.0, limit.size) * limit, -limit, limit)
        model.update(pose, q)
        to_world = rotation_z(pose[2])  # (vx, vy, ω) → (ẋ, ẏ, θ̇)
        world = model.jacobian_world()
        jacobian = np.hstack(((world[:, :3] @ to_world)[:, axes], world[:, 3:]))
        t0 = time.perf_counter()
        out = stage.filter(
            q,
            command,
            -limit,
            limit,
            base_pose=pose,
            base_axes=axes,
            base_velocity=measured,
            task_jacobian=jacobian,
        )
        (solved if out.changed else passed).append(time.perf_counter() - t0)
        rows.append(out.active)
        _counted(counts, out, counting)
    print(
        f'{robot.name:12s} {len(stage.collision.pairs):4d} pairs, {np.median(rows):3.0f} within the look-ahead '
        f'(median)   passed: {_figures(passed)}   QP: {_figures(solved)}   counting: {_figures(counting, 1)}'
    )


if __name__ == '__main__':
    main()
