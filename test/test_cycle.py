"""One orchestration of a period for both engines (:class:`wmm_control.cycle.Cycle`): inputs
checked as they come, the robot held on a refused or stale input, and the nodes and the direct
engine answering the same inputs with the same commands."""

import math

import numpy as np
import pinocchio as pin
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped, TwistStamped
from nav_msgs.msg import Odometry
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray

from ros_helpers import RosHarness, overrides
from sim_bridge.closed_loop import ClosedLoop
from sim_bridge.world import SimWorld
from wmm_control.base import make_base_controller
from wmm_control.cycle import Cycle
from wmm_control.experiments.direct import run_scenario
from wmm_control.experiments.ros_run import run_with_nodes
from wmm_control.experiments.scenario import load_scenario
from wmm_control.geometry import quaternion_from_yaw, se2_integrate
from wmm_control.nodes.qos import COMMAND_QOS, LATCHED_QOS, STATE_PUB_QOS
from wmm_control.nodes.redundancy_resolver import RedundancyResolverNode
from wmm_control.nodes.sim_timing import LOCKSTEP_TOPIC
from wmm_control.nodes.swmr_controller import SwmrControllerNode
from wmm_control.resolvers import make_resolver, method_parameters
from wmm_control.robot_config import load_robot


def _quat_xyzw(rotation):
    return pin.Quaternion(rotation).coeffs()


def _cycle(method='task_sharing', robot='steerable'):
    config = load_robot(robot)
    resolver = make_resolver(method, config)
    return Cycle(resolver, make_base_controller(config, config.period), config.period), config


def _step(cycle, config, now, q=None):
    n = config.arm.n
    q = np.asarray(config.start.arm, dtype=float) if q is None else q
    groups = {g: np.zeros(len(j)) for g, j in cycle.base_controller.command_groups.items()}
    return cycle.step(q, np.zeros(n), groups, None, now)


def test_the_cycle_holds_the_robot_on_a_refused_goal_and_on_stale_odometry():
    cycle, config = _cycle()
    period, rp = config.period, None
    rp = cycle.resolver_period
    start_pose = np.zeros(3)
    rp.odometry(start_pose[:2], (0, 0, 0, 1), np.zeros(3), 0.0)
    held = _step(cycle, config, 0.0)
    assert held.command is None and not held.stale  # no goal yet
    assert not np.any(held.arm_velocity) and not np.any(held.base.twist)
    good = np.array([1.5, 0.5, 1.0, 0.0, 0.0, 0.0, 1.0])
    assert [e.kind for e in rp.goal('world', good, 0.0)] == ['accepted']
    moving = _step(cycle, config, period)
    assert moving.command is not None and np.any(moving.arm_velocity) and np.any(moving.command.base_twist)
    # a goal with NaN, one inside the chassis, one in another frame: each refused, the robot held
    for bad, frame in (
        (np.full(7, math.nan), 'world'),
        (np.array([0.0, 0.0, 0.2, 0, 0, 0, 1]), 'world'),
        (good, 'map'),
    ):
        rp.odometry(start_pose[:2], (0, 0, 0, 1), np.zeros(3), 2 * period)
        assert [e.kind for e in rp.goal(frame, bad, 2 * period)] == ['rejected']
        answer = _step(cycle, config, 2 * period)
        assert answer.command is None and not np.any(answer.arm_velocity)
    # the same good goal again is taken; odometry older than state_timeout holds the robot
    rp.goal('world', good, 3 * period)
    stale = _step(cycle, config, 3 * period + rp.settings.state_timeout + 0.01)
    assert stale.command is None and stale.stale == 'no fresh /odom' and rp.stale_cycles == 1


def test_a_feasible_twist_beyond_reason_leaves_the_arm_command_uncompensated():
    cycle, config = _cycle()
    rp = cycle.resolver_period
    rp.odometry((0.0, 0.0), (0, 0, 0, 1), np.zeros(3), 0.0)
    rp.goal('world', np.array([2.0, 1.0, 1.0, 0.0, 0.0, 0.0, 1.0]), 0.0)
    plan = rp.plan(np.asarray(config.start.arm, dtype=float), np.zeros(config.arm.n), 0.0)
    rp.hold('k', plan.command)
    twist, events = rp.feasible_twist(np.array([1e308, 0.0, 0.0]))
    assert twist is None and [e.kind for e in events] == ['feasible twist']
    command, _ = rp.finish(twist)
    assert command is plan.command and rp.counters['compensation_dropped'] == 1


REFUSED_YAML = """scenario:
  name: refused_goal
  robot: steerable
  frame: world
  duration: 3.0
  goals:
    - {t: 0.0, pose: [1.2, 0.4, 1.0, pi/2, 0.0, 0.3]}
    - {t: 1.0, pose: [0.0, 0.0, 0.2, 0.0, 0.0, 0.0]}
    - {t: 2.0, pose: [1.0, -0.3, 1.0, pi/2, 0.0, 0.0]}
  experiment:
    runs:
      - {name: ts, method: task_sharing, feedback: ground_truth}
"""


def test_both_engines_hold_the_robot_on_a_goal_inside_its_body_and_go_on_alike(tmp_path):
    """A goal inside the chassis between two good ones: the resolver node and the direct engine
    both refuse it and hold the robot for that second (no command logged), then take the next
    goal, with the same commands (to the messages' round-off, amplified by the closed loop)."""
    path = tmp_path / 'refused.yaml'
    path.write_text(REFUSED_YAML)
    scenario = load_scenario(str(path))
    nodes = run_with_nodes(scenario, scenario.runs[0])
    world = SimWorld('steerable')
    direct = run_scenario(world, make_resolver('task_sharing', 'steerable'), scenario)
    world.close()
    for log in (nodes, direct):
        t = np.asarray(log.t)
        assert not np.any((t > 1.05) & (t < 1.95))  # held: the node publishes zeros, nothing is logged
        assert np.any(t < 1.0) and np.any(t > 2.05)
    # the nodes' goal reaches the resolver one period after the first state
    shift = 0.025
    for a, b in ((nodes, direct),):
        ta, tb = np.asarray(a.t), np.asarray(b.t) + shift
        common = [(i, int(np.argmin(np.abs(tb - x)))) for i, x in enumerate(ta) if np.min(np.abs(tb - x)) < 1e-6]
        assert len(common) > 60
        i, j = np.array(common).T
        np.testing.assert_allclose(np.asarray(a.arm_command)[i], np.asarray(b.arm_command)[j], atol=2e-3)


# ---------------------------------------------------------------------- the same bad inputs to both engines
GOOD_GOAL = (1.5, 0.5, 1.0, 0.0, 0.0, 0.0, 1.0)
NAN, INF = math.nan, math.inf

#: (name, frame, pose) of each goal refused: the robot is held until the next good goal
BAD_GOALS = (
    ('a NaN field', 'world', (1.5, NAN, 1.0, 0.0, 0.0, 0.0, 1.0)),
    ('another frame', 'map', GOOD_GOAL),
    ('beyond max_goal_distance', 'world', (60.0, 0.5, 1.0, 0.0, 0.0, 0.0, 1.0)),
    ('a zero quaternion', 'world', (1.5, 0.5, 1.0, 0.0, 0.0, 0.0, 0.0)),
    ('an infinite quaternion', 'world', (1.5, 0.5, 1.0, 0.0, 0.0, INF, 1.0)),
)


def _script():
    """Each period's inputs, in the order they come: ``(odometry, goal, joint state)``.

    ``odometry``: 'good', None (none comes) or a bad one (x NaN, twist infinite or a glitch's,
    zero quaternion); ``goal``: None or (frame, pose); ``joint state``: 'good', 'nan' (every joint
    NaN: both controllers refuse it) or 'drive inf' (a drive rate infinite: the drive joints
    are left out, the steer joints are enough)."""
    periods = [('good', None, 'good'), ('good', ('world', GOOD_GOAL), 'good'), ('good', None, 'good')]
    for _, frame, pose in BAD_GOALS:  # each refused and the robot held, then the good goal taken again
        periods += [('good', (frame, pose), 'good'), ('good', None, 'good'), ('good', ('world', GOOD_GOAL), 'good')]
    periods += [('x nan', None, 'good'), ('twist inf', None, 'good'), ('twist glitch', None, 'good')]
    periods += [('zero quaternion', None, 'good')]
    periods += [('good', None, 'nan'), ('good', None, 'good'), ('good', None, 'drive inf'), ('good', None, 'good')]
    periods += [(None, None, 'good')] * 11  # no odometry for longer than state_timeout: held, stale
    periods += [('good', None, 'good')] * 2
    return periods


class _Plant:
    """The measured state of both engines' robot: the joints and the odometry integrated with
    the last commands sent (the direct engine's; the test checks that the nodes sent the same)."""

    def __init__(self, config, groups, dt):
        self.dt = dt
        self.q = np.asarray(config.start.arm, dtype=float).copy()
        self.dq = np.zeros_like(self.q)
        self.base = {g: np.zeros(len(j)) for g, j in groups.items()}
        self.rates = {g: np.zeros(len(j)) for g, j in groups.items()}
        self.pose = np.zeros(3)
        self.twist = np.zeros(3)

    def odometry(self, kind):
        xy, quat, twist = self.pose[:2].copy(), quaternion_from_yaw(float(self.pose[2])), self.twist.copy()
        if kind == 'x nan':
            xy[0] = NAN
        elif kind == 'twist inf':
            twist[2] = INF
        elif kind == 'twist glitch':
            twist[0] = 1e3  # [m/s]
        elif kind == 'zero quaternion':
            quat = np.zeros(4)
        return xy, quat, twist

    def joints(self, kind):
        q, dq = self.q.copy(), self.dq.copy()
        base = {g: v.copy() for g, v in self.base.items()}
        rates = {g: v.copy() for g, v in self.rates.items()}
        if kind == 'nan':
            q[:] = NAN
            for g in base:
                base[g][:] = NAN
        elif kind == 'drive inf':
            rates['drive'][0] = INF
        return q, dq, base, rates

    def sent(self, arm, rates, twist):
        """The commands in force for the coming period."""
        self.dq, self.rates, self.twist = np.asarray(arm, dtype=float), rates, np.asarray(twist, dtype=float)

    def advance(self):
        self.q = self.q + self.dq * self.dt
        self.base = {g: self.base[g] + self.rates[g] * self.dt for g in self.base}
        self.pose = np.array(se2_integrate(self.pose, self.twist, self.dt))


class _NodeEngine:
    """The resolver and base controller nodes in one in-process executor, told that the simulator
    steps in lockstep: they age their inputs by the stamps of the joint states and await each
    other's answers (no wall-clock timing decides anything). This side plays the simulator:
    it publishes each input and spins until the nodes have taken it."""

    LOCKSTEP_TIMEOUT = 30.0  # [s] only a wait for an answer that never comes would last it

    def __init__(self, ros, method):
        self.ros = ros
        self.resolver = ros.add(
            RedundancyResolverNode(
                context=ros.context, parameter_overrides=overrides(method=method, markers_period=0.0)
            )
        )
        self.base = ros.add(SwmrControllerNode(context=ros.context))
        probe = ros.probe('engines_probe')
        timing = probe.create_publisher(Float64, LOCKSTEP_TOPIC, LATCHED_QOS)
        timing.publish(Float64(data=self.LOCKSTEP_TIMEOUT))
        self.pub_state = probe.create_publisher(JointState, '/joint_states', STATE_PUB_QOS)
        self.pub_odom = probe.create_publisher(Odometry, '/odom', STATE_PUB_QOS)
        self.pub_goal = probe.create_publisher(PoseStamped, '/goal_pose', COMMAND_QOS)
        self.got = {g: [] for g in ('arm', 'steer', 'drive')}
        for group, kept in self.got.items():
            probe.create_subscription(
                Float64MultiArray,
                f'/{group}_controller/commands',
                lambda m, kept=kept: kept.append(np.array(m.data)),
                50,
            )
        self.references = []
        probe.create_subscription(TwistStamped, '/base/reference', self.references.append, 50)
        # what each node was given and answered, recorded where the node hands it to the core
        self.events, self.reads = [], []
        self.resolver._log = lambda events: self.events.extend(events)
        arm_read, measured = self.resolver.arm.read, self.base.period.measured
        self.resolver.arm.read = lambda msg: self._kept(arm_read(msg))
        self.base.period.measured = lambda *a: self._kept(measured(*a))
        self.inputs = 0
        period = self.resolver.period
        for name in ('goal', 'odometry'):
            taken = getattr(period, name)
            setattr(period, name, lambda *a, taken=taken: self._taken(taken(*a)))
        r, b = self.resolver, self.base
        assert ros.spin_until(
            lambda: (
                r.watchdog.timing.lockstep
                and b.watchdog.timing.lockstep
                and r.resolver.safety.base_lag == b.base.lag
                and r.pub_arm.get_subscription_count() > 0
                and all(p.get_subscription_count() > 0 for p in b.pub_commands.values())
                and self.pub_state.get_subscription_count() >= 2
                and self.pub_odom.get_subscription_count() > 0
                and self.pub_goal.get_subscription_count() > 0
            )
        )
        self.names = list(r.arm_joints) + [j for g in b.groups for j in b.base.command_groups[g]]

    def _kept(self, read):
        self.reads.append(read[2])  # '' or why the node refused the joint state
        return read

    def _taken(self, events):
        self.inputs += 1
        return events

    def give(self, what, send):
        before = self.inputs
        send()
        assert self.ros.spin_until(lambda: self.inputs > before), f'{what} never reached the resolver'

    def odometry(self, xy, quat, twist, stamp):
        msg = Odometry()
        msg.header.stamp, msg.header.frame_id = stamp, 'odom'
        p, o, t = msg.pose.pose.position, msg.pose.pose.orientation, msg.twist.twist
        p.x, p.y = float(xy[0]), float(xy[1])
        o.x, o.y, o.z, o.w = (float(v) for v in quat)
        t.linear.x, t.linear.y, t.angular.z = (float(v) for v in twist)
        self.give('odometry', lambda: self.pub_odom.publish(msg))

    def goal(self, frame, pose, stamp):
        msg = PoseStamped()
        msg.header.stamp, msg.header.frame_id = stamp, frame
        p, o = msg.pose.position, msg.pose.orientation
        p.x, p.y, p.z, o.x, o.y, o.z, o.w = (float(v) for v in pose)
        self.give('goal', lambda: self.pub_goal.publish(msg))

    def state(self, q, dq, base, rates, stamp):
        """Publish the joint state; (arm command, rates per group, base reference) the nodes
        answered it with, or None when neither answered."""
        groups = self.base.groups
        msg = JointState(name=self.names)
        msg.header.stamp = stamp
        msg.position = [float(v) for v in np.concatenate([q, *(base[g] for g in groups)])]
        msg.velocity = [float(v) for v in np.concatenate([dq, *(rates[g] for g in groups)])]
        counts = {g: len(c) for g, c in self.got.items()}
        refs, reads = len(self.references), len(self.reads)
        self.pub_state.publish(msg)
        assert self.ros.spin_until(lambda: len(self.reads) >= reads + 2), 'the joint state never reached the nodes'
        if any(self.reads[reads:]):
            # refused: no answer can come (no timer runs meanwhile); the next state's answers are counted anew
            return None
        assert self.ros.spin_until(
            lambda: all(len(c) > counts[g] for g, c in self.got.items()) and len(self.references) > refs
        ), 'the nodes never answered the joint state'
        assert all(len(c) == counts[g] + 1 for g, c in self.got.items()), 'one answer per joint state'
        twist = self.references[-1].twist
        reference = np.array([twist.linear.x, twist.linear.y, twist.angular.z])
        return self.got['arm'][-1], {g: self.got[g][-1] for g in groups}, reference


def _stamp(t):
    return Time(sec=int(t), nanosec=int(round((t - int(t)) * 1e9)))


def test_both_engines_answer_the_same_bad_inputs_with_the_same_commands():
    """Goals with a NaN field, in another frame, beyond max_goal_distance, with a zero or an
    infinite quaternion; odometry with NaN, an infinite twist or a zero quaternion, and then none
    for longer than state_timeout; joint states all NaN, or with an infinite drive rate: the
    resolver and base controller nodes (in lockstep, one in-process executor) and the direct
    engine's :class:`Cycle` take or refuse each alike, log the same events, hold the robot in the
    same periods and answer every joint state with the same commands, none of them non-finite."""
    method = 'task_sharing'
    config = load_robot('steerable')
    ros = RosHarness(args=['--ros-args', '--disable-stdout-logs'])
    try:
        nodes = _NodeEngine(ros, method)
        p = nodes.resolver.p
        resolver = make_resolver(
            method,
            config,
            dt=p.period,
            **{n: getattr(p, n) for n in method_parameters(method) if n != 'dt' and hasattr(p, n)},
        )
        tolerance = nodes.base.p.applied_rate_tolerance
        cycle = Cycle(resolver, make_base_controller(config, p.period), p.period, applied_rate_tolerance=tolerance)
        rp = cycle.resolver_period
        plant = _Plant(config, cycle.base_controller.command_groups, p.period)
        clock, resync, held, refused, moved, seen = 0.0, True, [], 0, 0, set()
        for k, (odom, goal, joints) in enumerate(_script()):
            t = k * p.period
            events = []  # the direct engine's, in the order the node logs them
            nodes.events.clear()
            if odom is not None:  # inputs between two states: aged by the last state's time (lockstep)
                values = plant.odometry(odom)
                events += rp.odometry(*values, clock)
                nodes.odometry(*values, _stamp(t))
            if goal is not None:
                events += rp.goal(goal[0], np.asarray(goal[1], dtype=float), clock)
                nodes.goal(*goal, _stamp(t))
            q, dq, base, rates = plant.joints(joints)
            result = cycle.step(q, dq, base, rates, t, resync)
            answer = nodes.state(q, dq, base, rates, _stamp(t))
            events += result.events
            kinds = [e.kind for e in events if e.kind != 'joint_states rejected']
            seen.update(kinds)
            assert [e.kind for e in nodes.events] == kinds, (k, nodes.events, events)
            if result.rejected:
                refused += 1
                assert answer is None, f'period {k}: the nodes answered a joint state the cycle refused'
                assert result.rejected in nodes.reads[-2:], (result.rejected, nodes.reads[-2:])
                plant.advance()  # the commands in force stay
                continue
            assert answer is not None, f'period {k}: the cycle answered a joint state the nodes refused'
            clock, resync = t, False
            arm, node_rates, reference = answer
            direct_reference = np.zeros(3) if result.command is None else result.command.base_twist
            for got in (
                arm,
                reference,
                result.arm_velocity,
                direct_reference,
                *node_rates.values(),
                *result.base.rates.values(),
            ):
                assert np.all(np.isfinite(got)), f'period {k}: a non-finite command {got}'
            np.testing.assert_allclose(arm, result.arm_velocity, atol=1e-9, err_msg=f'period {k}')
            np.testing.assert_allclose(reference, direct_reference, atol=1e-9, err_msg=f'period {k}')
            for g, r in result.base.rates.items():
                np.testing.assert_allclose(node_rates[g], r, atol=1e-9, err_msg=f'period {k} {g}')
            if result.command is None:
                held.append((k, result.stale))
                assert not np.any(arm) and not np.any(reference)
            elif np.any(arm) and np.any(reference):
                moved += 1
            plant.sent(result.arm_velocity, result.base.rates, result.base.twist)
            plant.advance()
    finally:
        ros.close()
    # every kind of bad input met: goals refused, odometry refused, a joint state refused, stale odometry
    assert {'odom non-finite', 'odom twist', 'odom zero quaternion'} <= seen
    assert refused == 1 and rp.targets.rejected == len(BAD_GOALS)
    assert len([h for h in held if h[1] == 'no fresh /odom']) >= 3
    assert len([h for h in held if h[1] == '']) >= len(BAD_GOALS) + 1  # no goal, and after each refused one
    assert moved >= len(BAD_GOALS) + 10  # towards the good goal between them, and on the last odometry
    assert nodes.resolver.counters == rp.counters


def test_the_direct_engine_sends_nothing_for_a_joint_state_the_nodes_refuse(monkeypatch):
    """A joint state with NaN runs no cycle in :class:`~sim_bridge.closed_loop.ClosedLoop`, as in
    the nodes: no command is sent, the world steps under the commands in force, and the next
    state is answered again."""
    world = SimWorld('steerable')
    try:
        loop = ClosedLoop(world, make_resolver('task_sharing', 'steerable'))
        loop.cycle.resolver_period.goal('world', np.array(GOOD_GOAL), 0.0)
        for _ in range(3):
            moving = loop.step()
        assert moving.command is not None and np.any(moving.arm_velocity)
        sent = []
        monkeypatch.setattr(world, 'set_command', lambda group, values: sent.append(group))
        names, q, qd = world.joint_state()
        q[loop._arm[0]] = NAN
        monkeypatch.setattr(world, 'joint_state', lambda: (names, q, qd))
        t = world.time
        refused = loop.step()
        assert world.time > t and sent == [] and refused.command is None
        np.testing.assert_array_equal(refused.arm_velocity, moving.arm_velocity)  # still in force
        assert loop.events[-1].kind == 'joint_states rejected' and 'non-finite' in loop.events[-1].message
        monkeypatch.undo()
        assert loop.step().command is not None
    finally:
        world.close()
