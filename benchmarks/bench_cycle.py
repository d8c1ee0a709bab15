"""The whole control cycle per shipped robot, method and kind of state, against a pink IK step.
Prints figures, asserts nothing.

**The cycle** is :meth:`wmm_control.cycle.Cycle.step`, what a period of the direct engine runs:
the method (``step``, with the safety stage every method runs, then ``compensate`` where the
method uses it) and the robot's base controller (``make_base_controller``, open on its own
state: no measured wheel positions). Each cycle is timed on the wall clock
(``time.perf_counter``) and on the thread's CPU clock (``time.thread_time``), with the heap
kept as both engines keep it while they run periods (``wmm_control.cycle.steady_heap``: no
full pass of the garbage collector inside a period; pink is timed the same way).

**The states**, ``--states`` of each kind per robot (the same ones for every method):

* ``free``: free space, no obstacles: the periods of a closed-loop run (direct engine, AMP)
  through a goal in the arm's reach and one that needs the base, replayed in order.
* ``self``: the arm near its own body: random arm postures within the position limits (±π
  for an unlimited joint) whose closest pair with the robot's body or itself (not the floor)
  is within the safety stage's look-ahead distance and not in contact
  (``CollisionModel.within``), the base at its start pose and at rest.
* ``obstacles``: the base near ``table_pillar``'s table and pillar: random base poses around
  them (as ``bench_safety.py`` places them) at which a pair with an obstacle is within the
  stage's look-ahead for obstacles and nothing is in contact, the arm at its start posture, a
  measured base twist drawn within the base's velocity limits; the obstacles in the method's
  stage.

A ``self`` or ``obstacles`` state has arm rates drawn within a quarter of the velocity limits,
and a target: the end effector's pose moved by 0.05–1 m in a random direction and turned by up
to 0.5 rad about a random axis. Each of them is timed on the second of two periods: the first,
untimed, at the state one period earlier (the measured rates integrated back), so the method
and the base controller remember a running loop's last period, as the ``free`` states do from
the state before. Ten cycles run untimed before each timing, then the method and the base
controller are reset.

**The pink step**, on the same robot, at the same states and targets, timed in the same run
(before each method's cycles of each kind, and pooled per robot): ``Configuration.update`` at
the state (its kinematics, and with the barrier every pair's distance: the cycle computes its
own too) and ``solve_ik`` (quadprog) with a frame task on the end effector and a posture task
(``shared.PinkStep``); without and with pink's ``SelfCollisionBarrier`` over the robot's own
pairs (pink sees no obstacles). pink is installed for the benchmarks only (``bash
scripts/dev.sh bench``).

**The ratios** are to the median of the pink step *without* the barrier on the same robot:
the cycle's median over it, and the cycle's p99 over the same pink median (so "p99 ≤ 4× a
pink step" reads as the cycle's p99 within four median pink steps); on the wall clock, and on
the thread's CPU clock (both pink and the cycle), which leaves out the time the thread waited
for a core a busy machine gave to other work. The last two lines give, over every robot,
method and kind, the worst of each: the largest median ratio, the largest p99 ratio and the
longest cycle, each possibly from a different row; in CPU time, then on the wall clock::

    in thread CPU time: median N.NN× pink, p99 N.NN× pink, max N.NN ms
    cycle: median N.NN× pink, p99 N.NN× pink, max N.NN ms

    python benchmarks/bench_cycle.py [--states 300] [--robots steerable,...] [--methods pinv,...]
                                     [--kinds free,self,obstacles]

**The robots**: every shipped one, and PAL's TIAGo with its hand (``tiago``, a real description
with mesh collision shapes, 779 pairs of shapes checked) where the ``example-robot-data`` wheel
is installed (the test requirements install it), set up with ``wmm_robot init`` as
docs/robots.md gives it; ``tiago_no_hand`` on request.
"""

import argparse
import functools
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a source checkout
sys.path.insert(0, str(Path(__file__).resolve().parent))  # the benchmarks' shared code

from shared import TIAGO, PinkStep, closed_loop_states, pink_installed, set_up_tiago, tiago_share  # noqa: E402
from wmm_control.base import make_base_controller  # noqa: E402
from wmm_control.cycle import Cycle, steady_heap  # noqa: E402
from wmm_control.geometry import quaternion_from_matrix, quaternion_from_yaw  # noqa: E402
from wmm_control.kinematics.workspace import Workspace  # noqa: E402
from wmm_control.kinematics import KinematicModel  # noqa: E402
from wmm_control.kinematics.collision import FLOOR  # noqa: E402
from wmm_control.kinematics.obstacles import load_obstacles  # noqa: E402
from wmm_control.resolvers import PoseTarget, RobotState, make_resolver  # noqa: E402
from wmm_control.resolvers.safety import SafetyStage  # noqa: E402
from wmm_control.robot_config import load_robot, robot_names  # noqa: E402

METHODS = ('pinv', 'task_sharing', 'amp', 'traditional')
KINDS = ('free', 'self', 'obstacles')
OBSTACLES = 'table_pillar'
#: where the base is drawn for the ``obstacles`` states: (x, y, θ) low and high [m, m, rad]
#: (around the table and the pillar, as in ``bench_safety.py``)
BASE_BOX = ((0.2, -1.6, -np.pi), (2.8, 1.6, np.pi))
WARM_UP = 10


@dataclass(frozen=True)
class Sample:
    """One timed state: ``state`` and ``target``; ``previous``, the state one period earlier,
    run untimed first (None: the sample before it is that period)."""

    state: RobotState
    target: PoseTarget
    previous: RobotState | None = None


@functools.cache
def _goal_checks(model):
    """The workspace of ``model`` and the obstacles: what a goal is checked against."""
    return Workspace(model), load_obstacles(OBSTACLES)


def _moved_target(model, base_pose, q_arm, rng):
    """The end effector's pose at (``base_pose``, ``q_arm``), moved by 0.05–1 m in a random
    direction and turned by up to 0.5 rad about a random axis: a goal the resolver takes (not
    below the floor, above the arm's reach nor inside the body or an obstacle)."""
    model.update(base_pose, q_arm)
    position, rotation = model.ee_placement_world()
    workspace, obstacles = _goal_checks(model)
    while True:
        direction, axis = rng.normal(size=3), rng.normal(size=3)
        offset = direction / np.linalg.norm(direction) * rng.uniform(0.05, 1.0)
        if not workspace.impossible(position + offset, base_pose, obstacles):
            break
    turn = Rotation.from_rotvec(axis / np.linalg.norm(axis) * rng.uniform(0.0, 0.5))
    return PoseTarget(position + offset, turn.as_matrix() @ rotation)


def _sample(cfg, model, base_pose, q_arm, dq_arm, base_twist, rng):
    """A :class:`Sample` at this state, with the state one period earlier (rates integrated back)."""
    dt = cfg.period
    theta = base_pose[2]
    world = Rotation.from_euler('z', theta).apply(np.array([base_twist[0], base_twist[1], 0.0]))
    before = np.array([base_pose[0] - dt * world[0], base_pose[1] - dt * world[1], theta - dt * base_twist[2]])
    return Sample(
        RobotState(base_pose, base_twist, q_arm, dq_arm),
        _moved_target(model, base_pose, q_arm, rng),
        RobotState(before, base_twist, q_arm - dt * dq_arm, dq_arm),
    )


def free_states(cfg, count, rng):
    """``count`` periods of a closed-loop run in free space (see the module docstring)."""
    return [Sample(state, target) for state, target, _ in closed_loop_states(cfg, count)]


def self_states(cfg, count, rng):
    """``count`` random arm postures near the robot's own body (see the module docstring)."""
    model, arm = KinematicModel(cfg), cfg.arm
    stage = SafetyStage.for_robot(cfg, kinematics=model)
    lower = np.where(np.isfinite(arm.position_lower), arm.position_lower, -np.pi)
    upper = np.where(np.isfinite(arm.position_upper), arm.position_upper, np.pi)
    pose = np.asarray(cfg.start.base_pose, dtype=float)
    out = []
    while len(out) < count:
        q = rng.uniform(lower, upper)
        near, closest, _ = stage.collision.within(q, stage.params.collision_lookahead, pose)
        if closest <= 0.0 or not any(FLOOR not in pair for pair in near.links):
            continue
        dq = rng.uniform(-0.25, 0.25, arm.velocity.size) * arm.velocity
        out.append(_sample(cfg, model, pose, q, dq, np.zeros(3), rng))
    return out


def obstacle_states(cfg, count, rng):
    """``count`` random base poses near ``table_pillar``'s obstacles (see the module docstring)."""
    obstacles = load_obstacles(OBSTACLES)
    names = {o.name for o in obstacles}
    model, arm = KinematicModel(cfg), cfg.arm
    stage = SafetyStage.for_robot(cfg, obstacles=obstacles, kinematics=model)
    q = np.asarray(cfg.start.arm, dtype=float)
    out = []
    while len(out) < count:
        pose = rng.uniform(*BASE_BOX)
        near, closest, _ = stage.collision.within(q, stage.obstacle_lookahead, pose)
        if closest <= 0.0 or not any(names & set(pair) for pair in near.links):
            continue
        twist = rng.uniform(-1.0, 1.0, 3) * cfg.base.velocity
        dq = rng.uniform(-0.25, 0.25, arm.velocity.size) * arm.velocity
        out.append(_sample(cfg, model, pose, q, dq, twist, rng))
    return out


STATES = {'free': free_states, 'self': self_states, 'obstacles': obstacle_states}


def _feed(cycle, state, target, now):
    """Give ``cycle`` the odometry of ``state`` and ``target`` as a goal at ``now`` [s], as the
    resolver node's callbacks do between two joint states (untimed: not the cycle's work)."""
    period = cycle.resolver_period
    x, y, theta = state.base_pose
    period.odometry((x, y), quaternion_from_yaw(theta), state.base_twist, now)
    pose = np.concatenate((target.position, quaternion_from_matrix(target.rotation)))
    period.goal('world', pose, now)


def _step(cycle, state, now):
    """One :meth:`Cycle.step` on ``state``'s arm (the base's wheels not measured: its controller
    goes on from its own state)."""
    return cycle.step(state.q_arm, state.dq_arm, None, None, now)


def time_cycles(cfg, method, kind, samples):
    """Wall and thread CPU time [s] of :meth:`Cycle.step` at each sample. Shape (2, len(samples))."""
    resolver = make_resolver(method, cfg)
    cycle = Cycle(resolver, make_base_controller(cfg, cfg.period), cfg.period)
    if kind == 'obstacles':
        cycle.resolver_period.set_obstacles(load_obstacles(OBSTACLES))
    now = 0.0
    for s in samples[:WARM_UP]:
        _feed(cycle, s.state, s.target, now)
        _step(cycle, s.state, now)
        now += cfg.period
    resolver.reset()
    cycle.base_controller.reset()
    times = np.empty((2, len(samples)))
    with steady_heap():  # as both engines run their periods: no full pass of the collector inside
        for k, s in enumerate(samples):
            if s.previous is not None:
                _feed(cycle, s.previous, s.target, now)
                _step(cycle, s.previous, now)
                now += cfg.period
            _feed(cycle, s.state, s.target, now)
            w0, c0 = time.perf_counter(), time.thread_time()
            _step(cycle, s.state, now)
            c1, w1 = time.thread_time(), time.perf_counter()
            now += cfg.period
            times[:, k] = w1 - w0, c1 - c0
    return times


def time_pink(step, samples):
    """pink's update + solve at each sample, wall and thread CPU time [s], and the wall time of
    its solve alone (shape (3, len(samples))), and how many of the solves found no solution
    (timed all the same)."""
    for s in samples[:WARM_UP]:
        step.update(step.configuration(s.state.base_pose, s.state.q_arm))
        step.set_target(s.target.position, s.target.rotation)
        step.solve()
    times, failed = np.empty((3, len(samples))), 0
    with steady_heap():  # the same heap as the cycles are timed with
        for k, s in enumerate(samples):
            q = step.configuration(s.state.base_pose, s.state.q_arm)
            w0, c0 = time.perf_counter(), time.thread_time()
            step.update(q)
            step.set_target(s.target.position, s.target.rotation)
            w1 = time.perf_counter()
            velocity = step.solve()
            c2, w2 = time.thread_time(), time.perf_counter()
            times[:, k] = w2 - w0, c2 - c0, w2 - w1
            failed += velocity is None
    return times, failed


def _stats(seconds):
    """(median, p99, max) [µs]."""
    us = np.asarray(seconds) * 1e6
    return float(np.median(us)), float(np.percentile(us, 99)), float(us.max())


def _cells(stats):
    return ' / '.join(f'{v:.0f}' for v in stats)


def run(robots, methods, kinds, count, seed=0):
    """Time every robot × method × kind; print the tables and the last line. Returns the rows.
    ``robots``: shipped robot names, and :data:`~shared.TIAGO` names (set up here with ``init``)."""
    with tempfile.TemporaryDirectory() as folder:
        robots = [set_up_tiago(name, folder) if name in TIAGO else name for name in robots]
        return _run(robots, methods, kinds, count, seed)


def _run(robots, methods, kinds, count, seed):
    print(f'## The whole cycle, {count} states of each kind: median / p99 / max [µs], ratios to pink\'s median\n')
    print('| robot | method | kind | wall | thread CPU | wall: median, p99 / pink | CPU: median, p99 / pink |')
    print('|---|---|---|---|---|---|---|')
    rows, pinks = [], {}
    for robot in robots:
        cfg = load_robot(robot)
        name = cfg.name
        rng = np.random.default_rng(seed)
        samples = {kind: STATES[kind](cfg, count, rng) for kind in kinds}
        steps = {'plain': PinkStep(cfg), 'barrier': PinkStep(cfg, barrier=True)}
        pink = {variant: [] for variant in steps}
        robot_rows = []
        for method in methods:
            for kind in kinds:
                for variant, step in steps.items():
                    pink[variant].append(time_pink(step, samples[kind]))
                robot_rows.append((method, kind, time_cycles(cfg, method, kind, samples[kind])))
        pinks[name] = {'pairs': steps['barrier'].pairs}
        for variant, runs in pink.items():
            times = np.hstack([t for t, _ in runs])
            pinks[name][variant] = ([_stats(t) for t in times], sum(f for _, f in runs), times.shape[1])
        (wall_pink, cpu_pink, _), _, _ = pinks[name]['plain']
        for method, kind, times in robot_rows:
            wall, cpu = _stats(times[0]), _stats(times[1])
            ratios = (wall[0] / wall_pink[0], wall[1] / wall_pink[0], cpu[0] / cpu_pink[0], cpu[1] / cpu_pink[0])
            rows.append((name, method, kind, wall, cpu, ratios))
            print(
                f'| {name} | {method} | {kind} | {_cells(wall)} | {_cells(cpu)} '
                f'| {ratios[0]:.2f}×, {ratios[1]:.2f}× | {ratios[2]:.2f}×, {ratios[3]:.2f}× |',
                flush=True,
            )
    print('\n## One pink step on the same robot and states: median / p99 / max [µs]\n')
    print(
        '| robot | update + solve_ik: wall | CPU | solve_ik alone | with the barrier: wall | CPU | solve_ik alone | pairs |'
    )
    print('|---|---|---|---|---|---|---|---|')
    for name, p in pinks.items():
        cells = ' | '.join(_cells(stats) for variant in ('plain', 'barrier') for stats in p[variant][0])
        print(f'| {name} | {cells} | {p["pairs"]} |')
    for name, p in pinks.items():
        for variant in ('plain', 'barrier'):
            _, failed, steps = p[variant]
            if failed:
                print(f'\n{name}, pink {variant}: {failed} of {steps} steps found no solution (timed all the same)')
    worst = [max(row[5][k] for row in rows) for k in range(4)]
    longest_wall, longest_cpu = (max(row[k][2] for row in rows) / 1e3 for k in (3, 4))
    print(f'\nin thread CPU time: median {worst[2]:.2f}× pink, p99 {worst[3]:.2f}× pink, max {longest_cpu:.2f} ms')
    print(f'cycle: median {worst[0]:.2f}× pink, p99 {worst[1]:.2f}× pink, max {longest_wall:.2f} ms')
    return rows


def _choice(text, allowed, what):
    chosen = [v for v in text.split(',') if v]
    unknown = sorted(set(chosen) - set(allowed))
    if unknown or not chosen:
        raise SystemExit(f'--{what}: unknown {unknown}, expected some of {list(allowed)}')
    return chosen


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--states', type=int, default=300, help='states of each kind per robot (default: %(default)s)')
    robots = list(robot_names()) + (list(TIAGO) if tiago_share() is not None else [])
    parser.add_argument(
        '--robots',
        default=','.join(robots[:-1]),
        help='comma-separated (default: %(default)s; tiago_no_hand too where example-robot-data is installed)',
    )
    parser.add_argument('--methods', default=','.join(METHODS), help='comma-separated (default: %(default)s)')
    parser.add_argument('--kinds', default=','.join(KINDS), help='comma-separated (default: %(default)s)')
    args = parser.parse_args(argv)
    robots = _choice(args.robots, robots, 'robots')
    methods, kinds = _choice(args.methods, METHODS, 'methods'), _choice(args.kinds, KINDS, 'kinds')
    if args.states <= WARM_UP:
        raise SystemExit(f'--states must be more than {WARM_UP}, got {args.states}')
    if not pink_installed():
        print('pink not installed (pip install pin-pink quadprog; bash scripts/dev.sh bench does): no yardstick')
        return 1
    run(robots, methods, kinds, args.states)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
