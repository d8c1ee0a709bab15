"""The ``goal_planner`` node's decisions in the closed loop, ROS-free: a goal behind
``table_pillar``'s table pursued by :class:`~wmm_control.planning.pursuit.GoalPursuit` on the
direct engine (:class:`~sim_bridge.closed_loop.ClosedLoop`, ground-truth feedback), one run per
method. Prints figures, asserts nothing.

Each period does what the node does: ``pursuit.step`` with the true base pose and arm joints,
then the resolver's cycle with what it gave (a trajectory point, the goal, a hold). The world
steps on while a plan is made, paced at real time then (a period of wall time per period, as a
realtime simulator steps; unpaced, a held robot's periods are so cheap that a plan under load
would take minutes of simulated time). Per method: the outcome (reached,
with the simulated time; or the pursuit's state and the end effector's error at the end), the
plans made, the planning time, and the wall time of ``pursuit.step`` (median / p99 / max [ms]),
over every period and over the periods while the worker planned: the period does not wait for a
plan.

    python benchmarks/bench_pursuit.py [--robot steerable] [--methods pinv,task_sharing,amp,traditional]
        [--goal 2.4,-0.2,1.0] [--yaw 1.5708] [--duration 60]
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run from a source checkout

from sim_bridge.closed_loop import ClosedLoop  # noqa: E402
from sim_bridge.world import SimWorld  # noqa: E402
from wmm_control.geometry import matrix_from_quaternion, quaternion_from_matrix, rotation_angle, rotation_z  # noqa: E402
from wmm_control.kinematics.obstacles import load_obstacles  # noqa: E402
from wmm_control.planning.pursuit import GoalPursuit, PursuitState  # noqa: E402
from wmm_control.resolvers import make_resolver  # noqa: E402
from wmm_control.resolvers.interface import PoseTarget  # noqa: E402
from wmm_control.robot_config import load_robot  # noqa: E402

TOLERANCE = (0.01, 0.02)  # [m, rad] the resolver node's goal_tolerance
HELD = 20  # periods within the tolerance that count as reached


def ms(values):
    """'median / p99 / max' of ``values`` [s], in ms."""
    v = 1e3 * np.asarray(values, dtype=float)
    if not v.size:
        return '-'
    return f'{np.median(v):.2f} / {np.percentile(v, 99):.2f} / {np.max(v):.2f}'


def run(robot, method, goal, yaw, duration, obstacles):
    with SimWorld(robot, base_mode='kinematic') as world:
        world.set_obstacles(obstacles)
        loop = ClosedLoop(world, make_resolver(method, robot), feedback='ground_truth')
        loop.set_obstacles(obstacles)
        rotation = rotation_z(yaw) @ matrix_from_quaternion(world.ee_pose()[1])
        target = PoseTarget(goal, rotation)
        pursuit = GoalPursuit(robot, obstacles, 'world', 50.0)
        arm = [world.joint_names.index(n) for n in robot.arm.joints]
        pursuit.new_goal('world', np.concatenate((goal, quaternion_from_matrix(rotation))))
        step_s, planning_step_s, held, outcome = [], [], 0, None
        try:
            for _ in range(int(round(duration / robot.period))):
                _, q, _ = world.joint_state()
                planning = pursuit.state is PursuitState.PLANNING
                began = time.perf_counter()
                out = pursuit.step(robot.period, world.base_pose(), q[arm])
                spent = time.perf_counter() - began
                (planning_step_s if planning else step_s).append(spent)
                if planning:  # the world at real time while the worker plans
                    time.sleep(max(0.0, robot.period - spent))
                given, tracking = None, None
                if out.hold is not None:
                    given, tracking = out.hold, False
                if out.forward_goal:
                    given, tracking = target, False
                if out.reference is not None:
                    given, tracking = out.reference, True
                rec = loop.step(given, tracking)
                errors = (np.linalg.norm(rec.ee_position - goal), rotation_angle(rotation, rec.ee_rotation))
                held = held + 1 if errors[0] < TOLERANCE[0] and errors[1] < TOLERANCE[1] else 0
                if held >= HELD:
                    outcome = f'reached at {world.time:.1f} s'
                    break
        finally:
            pursuit.close()
        if outcome is None:
            outcome = f'{pursuit.state.value} at {duration:g} s, {errors[0]:.3f} m / {errors[1]:.3f} rad off'
        c = pursuit.counters
        print(
            f'{method:>13}: {outcome}; {c.plans} plans ({c.replans} again), last planned in '
            f'{pursuit.planning_time:.2f} s; pursuit.step [ms] {ms(step_s + planning_step_s)}, '
            f'while planning {ms(planning_step_s)}'
        )


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--robot', default='steerable')
    parser.add_argument('--methods', default='pinv,task_sharing,amp,traditional')
    parser.add_argument('--goal', default='2.4,-0.2,1.0', help='x,y,z [m], behind the table by default')
    parser.add_argument(
        '--yaw', type=float, default=0.5 * np.pi, help='the goal orientation: the start one turned about z [rad]'
    )
    parser.add_argument('--duration', type=float, default=60.0, help='simulated time per run [s]')
    parser.add_argument('--obstacles', default='table_pillar')
    args = parser.parse_args(argv)
    robot = load_robot(args.robot)
    goal = np.array([float(v) for v in args.goal.split(',')])
    print(f'robot {robot.name}, goal {goal.tolist()} (yaw {args.yaw:.3f} rad), obstacles {args.obstacles}')
    for method in args.methods.split(','):
        run(robot, method, goal, args.yaw, args.duration, load_obstacles(args.obstacles))


if __name__ == '__main__':
    main()
