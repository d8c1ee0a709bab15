"""The planner's cost and outcome per goal: where to stand, the base path (OMPL), its timing.
Prints figures, asserts nothing.

For each robot, the goals ``wmm_randomized`` draws for an obstacle file (its ``goal_region``,
seed 0), each planned from the robot's start pose with ``GoalPlanner``'s defaults: the wall
time of the chosen base path, of the rest (the stance search and the paths searched to
stances not taken) and of the whole plan (median, p99 and max
[s]), how many goals got a plan (the others with their reason), whether the path was the
straight motion or RRT-Connect's, the path's length, and the trajectory's duration.

    python benchmarks/bench_planning.py [--robots steerable,panda_diff] [--goals 20] [--obstacles table_pillar]
"""

import argparse
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run from a source checkout

from wmm_control.experiments.randomized import sample_goals  # noqa: E402
from wmm_control.geometry import matrix_from_rpy  # noqa: E402
from wmm_control.kinematics.obstacles import load_obstacles  # noqa: E402
from wmm_control.planning import GoalPlanner  # noqa: E402
from wmm_control.robot_config import load_robot, robot_names  # noqa: E402


def figures(values):
    """'median / p99 / max' of ``values`` [s]."""
    v = np.asarray(values, dtype=float)
    return f'{np.median(v):.3f} / {np.percentile(v, 99):.3f} / {np.max(v):.3f}'


def bench(robot, goals, obstacles):
    cfg = load_robot(robot)
    planner = GoalPlanner(cfg, load_obstacles(obstacles))
    stance_s, path_s, total_s, lengths, durations = [], [], [], [], []
    outcomes, planners = Counter(), Counter()
    for goal in sample_goals(cfg, goals, seed=0, obstacles=obstacles):
        t0 = time.perf_counter()
        plan = planner.plan(goal.pose[:3], matrix_from_rpy(goal.pose[3:]), cfg.start.base_pose)
        total_s.append(time.perf_counter() - t0)
        outcomes[plan.no_way.value if plan.no_way else 'planned'] += 1
        if plan.path is not None:
            path_s.append(plan.path.planning_time)
            stance_s.append(total_s[-1] - plan.path.planning_time)
        if plan.trajectory is not None:
            planners[plan.path.planner] += 1
            lengths.append(float(np.sum(np.hypot(*np.diff(plan.path.waypoints[:, :2], axis=0).T))))
            durations.append(plan.trajectory.duration)
    print(f'{robot} ({cfg.base.family}), {goals} goals of {obstacles}: {dict(outcomes)}; paths: {dict(planners)}')
    print(f'  whole plan [s] median / p99 / max: {figures(total_s)}')
    if path_s:
        print(
            f'  the rest (stance search, paths to stances not taken) [s]: {figures(stance_s)}; '
            f'base path (search + simplification + checks) [s]: {figures(path_s)}'
        )
    if lengths:
        print(
            f'  waypoint polyline [m] median {np.median(lengths):.2f}, max {np.max(lengths):.2f}; '
            f'trajectory [s] median {np.median(durations):.1f}, max {np.max(durations):.1f}'
        )


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--robots', default=','.join(robot_names()))
    parser.add_argument('--goals', type=int, default=20)
    parser.add_argument('--obstacles', default='table_pillar')
    args = parser.parse_args(argv)
    for robot in args.robots.split(','):
        bench(robot, args.goals, args.obstacles)


if __name__ == '__main__':
    main()
