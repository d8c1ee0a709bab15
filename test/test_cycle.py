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
from wmm_control.resolvers.period import ResolverSettings
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


def _script(stale_periods):
    """Each period's inputs, in the order they come: ``(odometry, goal, joint state)``.

    ``odometry``: 'good', None (none comes) or a bad one (x NaN, twist infinite or a glitch's,
    zero quaternion); ``goal``: None or (frame, pose); ``joint state``: 'good', 'nan' (every
    joint NaN: both controllers refuse it), 'arm nan' (the resolver refuses it, the base
    controller answers), 'steer nan' (the reverse: the steer joints are required) or
    'drive inf' (a drive rate infinite: the drive joints are left out, the steer joints are
    enough). ``stale_periods``: how many periods the odometry stops for."""
    periods = [('good', None, 'good'), ('good', ('world', GOOD_GOAL), 'good'), ('good', None, 'good')]
    for _, frame, pose in BAD_GOALS:  # each refused and the robot held, then the good goal taken again
        periods += [('good', (frame, pose), 'good'), ('good', None, 'good'), ('good', ('world', GOOD_GOAL), 'good')]
    periods += [('x nan', None, 'good'), ('twist inf', None, 'good'), ('twist glitch', None, 'good')]
    periods += [('zero quaternion', None, 'good')]
    for joints in ('nan', 'arm nan', 'steer nan', 'drive inf'):
        periods += [('good', None, joints), ('good', None, 'good')]
    periods += [(None, None, 'good')] * stale_periods  # no odometry for longer than state_timeout: held, stale
    periods += [('good', None, 'good')] * 2
    return periods


class _Plant:
    """The measured state of both engines' robot: the joints and the odometry integrated with
    the commands in force (the direct engine's; the test checks that the nodes sent the same)."""

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
        if kind in ('nan', 'arm nan'):
            q[0] = NAN
        if kind in ('nan', 'steer nan'):
            base['steer'][:] = NAN
        if kind == 'drive inf':
            rates['drive'][0] = INF
        return q, dq, base, rates

    def step(self, arm, base):
        """One period under ``arm`` rates and ``base`` (:class:`~wmm_control.base.period.PeriodAnswer`)
        when they were sent, else the commands in force."""
        if arm is not None:
            self.dq = np.asarray(arm, dtype=float)
        if base is not None:
            self.rates, self.twist = base.rates, np.asarray(base.twist, dtype=float)
        self.q = self.q + self.dq * self.dt
        self.base = {g: self.base[g] + self.rates[g] * self.dt for g in self.base}
        self.pose = np.array(se2_integrate(self.pose, self.twist, self.dt))


class _NodeEngine:
    """The resolver and base controller nodes in one in-process executor, told that the simulator
    steps in lockstep: they age their inputs by the stamps of the joint states and await each
    other's answers. This side plays the simulator: it publishes each input and spins until the
    nodes have taken it, and each joint state until the answers the direct engine gave came.

    Every wait for an answer is ``WAIT`` s of wall time, and the joint-state watchdogs allow a
    second more than that: only a wait for an answer that never comes (a controller whose
    joints were refused) lasts it; no wall-clock timing decides anything."""

    WAIT = 1.0  # [s]

    def __init__(self, ros, method):
        self.ros = ros
        wait, timeout = self.WAIT, self.WAIT + 1.0
        self.resolver = ros.add(
            RedundancyResolverNode(
                context=ros.context,
                parameter_overrides=overrides(
                    method=method, markers_period=0.0, compensation_timeout=wait, state_timeout=timeout
                ),
            )
        )
        self.base = ros.add(
            SwmrControllerNode(
                context=ros.context, parameter_overrides=overrides(reference_wait=wait, joint_state_timeout=timeout)
            )
        )
        probe = ros.probe('engines_probe')
        timing = probe.create_publisher(Float64, LOCKSTEP_TOPIC, LATCHED_QOS)
        timing.publish(Float64(data=wait))
        self.pub_state = probe.create_publisher(JointState, '/joint_states', STATE_PUB_QOS)
        self.pub_odom = probe.create_publisher(Odometry, '/odom', STATE_PUB_QOS)
        self.pub_goal = probe.create_publisher(PoseStamped, '/goal_pose', COMMAND_QOS)
        self.got = {g: [] for g in ('arm', 'steer', 'drive', 'reference')}
        for group in ('arm', 'steer', 'drive'):
            probe.create_subscription(
                Float64MultiArray,
                f'/{group}_controller/commands',
                lambda m, kept=self.got[group]: kept.append(np.array(m.data)),
                50,
            )
        probe.create_subscription(
            TwistStamped,
            '/base/reference',
            lambda m: self.got['reference'].append(np.array([m.twist.linear.x, m.twist.linear.y, m.twist.angular.z])),
            50,
        )
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

    def state(self, q, dq, base, rates, stamp, arm, base_answer):
        """Publish the joint state and spin until the nodes took it and sent what the direct
        engine sent for it (``arm``: an arm command and a base reference; ``base_answer``: rates
        per group). Returns {topic: message} of what came; a message the direct engine did not
        send shows as one too many, here or at the next state."""
        groups = self.base.groups
        msg = JointState(name=self.names)
        msg.header.stamp = stamp
        msg.position = [float(v) for v in np.concatenate([q, *(base[g] for g in groups)])]
        msg.velocity = [float(v) for v in np.concatenate([dq, *(rates[g] for g in groups)])]
        counts = {g: len(c) for g, c in self.got.items()}
        expected = {'arm': arm, 'reference': arm, 'steer': base_answer, 'drive': base_answer}
        reads = len(self.reads)
        self.pub_state.publish(msg)
        assert self.ros.spin_until(lambda: len(self.reads) >= reads + 2), 'the joint state never reached the nodes'
        assert self.ros.spin_until(
            lambda: all(len(self.got[g]) >= counts[g] + want for g, want in expected.items()), timeout=10 * self.WAIT
        ), f'the nodes did not answer the joint state: {[(g, len(c) - counts[g]) for g, c in self.got.items()]}'
        came = {g: len(c) - counts[g] for g, c in self.got.items()}
        assert came == {g: int(want) for g, want in expected.items()}, came
        return {g: c[-1] for g, c in self.got.items() if came[g]}


def _stamp(t):
    return Time(sec=int(t), nanosec=int(round((t - int(t)) * 1e9)))


def test_both_engines_answer_the_same_bad_inputs_with_the_same_commands():
    """Goals with a NaN field, in another frame, beyond max_goal_distance, with a zero or an
    infinite quaternion; odometry with NaN, an infinite twist, a glitch's twist or a zero
    quaternion, and then none for longer than state_timeout; joint states with NaN in every
    joint, in the arm's, in the steer joints', or an infinite drive rate: the resolver and base
    controller nodes (in lockstep, one in-process executor) and the direct engine's
    :class:`Cycle` take or refuse each alike, log the same events, hold the robot in the same
    periods and answer every joint state with the same commands, none of them non-finite."""
    method = 'task_sharing'
    config = load_robot('steerable')
    ros = RosHarness(args=['--ros-args', '--disable-stdout-logs'])
    try:
        nodes = _NodeEngine(ros, method)
        p, b = nodes.resolver.p, nodes.base.p
        resolver = make_resolver(
            method,
            config,
            dt=p.period,
            **{n: getattr(p, n) for n in method_parameters(method) if n != 'dt' and hasattr(p, n)},
        )
        cycle = Cycle(
            resolver,
            make_base_controller(config, p.period),
            p.period,
            ResolverSettings.defaults(state_timeout=p.state_timeout),
            b.applied_rate_tolerance,
            b.reference_timeout,
        )
        rp = cycle.resolver_period
        plant = _Plant(config, cycle.base_controller.command_groups, p.period)
        clock, resync, held, refused, moved, seen = 0.0, True, [], [], 0, set()
        for k, (odom, goal, joints) in enumerate(_script(int(p.state_timeout / p.period) + 3)):
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
            arm_sent, base_sent = result.arm_velocity is not None, result.base is not None
            answer = nodes.state(q, dq, base, rates, _stamp(t), arm_sent, base_sent)
            events += result.events
            kinds = [e.kind for e in events if e.kind != 'joint_states rejected']
            seen.update(kinds)
            assert [e.kind for e in nodes.events] == kinds, (k, nodes.events, events)
            if result.rejected:
                refused.append((joints, arm_sent, base_sent))
                assert result.rejected in nodes.reads[-2:], (result.rejected, nodes.reads[-2:])
            else:
                clock, resync = t, False  # the resolver ages its inputs by the last state it took
            if arm_sent:
                clock = t
                reference = np.zeros(3) if result.command is None else result.command.base_twist
                np.testing.assert_allclose(answer['arm'], result.arm_velocity, atol=1e-9, err_msg=f'period {k}')
                np.testing.assert_allclose(answer['reference'], reference, atol=1e-9, err_msg=f'period {k}')
                if result.command is None:
                    held.append((k, result.stale))
                    assert not np.any(answer['arm']) and not np.any(answer['reference'])
                elif np.any(answer['arm']) and np.any(answer['reference']):
                    moved += 1
            if base_sent:
                for g, r in result.base.rates.items():
                    np.testing.assert_allclose(answer[g], r, atol=1e-9, err_msg=f'period {k} {g}')
            for got in answer.values():
                assert np.all(np.isfinite(got)), f'period {k}: a non-finite command {got}'
            plant.step(result.arm_velocity, result.base)
    finally:
        ros.close()
    # every kind of bad input met: goals refused, odometry refused, joints refused, stale odometry
    assert {'odom non-finite', 'odom twist', 'odom zero quaternion'} <= seen
    assert refused == [('nan', False, False), ('arm nan', False, True), ('steer nan', True, False)]
    assert rp.targets.rejected == len(BAD_GOALS) and rp.counters['compensation_dropped'] == 1
    assert len([h for h in held if h[1] == 'no fresh /odom']) >= 3
    assert len([h for h in held if h[1] == '']) >= len(BAD_GOALS) + 1  # no goal, and after each refused one
    assert moved >= len(BAD_GOALS) + 10  # towards the good goal between them, and on the last odometry
    assert nodes.resolver.counters == rp.counters


def test_the_direct_engine_sends_what_the_nodes_send_for_refused_joints(monkeypatch):
    """In :class:`~sim_bridge.closed_loop.ClosedLoop`, as in the nodes: a joint state with NaN
    in the arm's joints sends the base's rates alone, one with NaN in every joint sends nothing;
    the world steps under the commands in force, and the next state is answered again."""
    world = SimWorld('steerable')
    try:
        loop = ClosedLoop(world, make_resolver('task_sharing', 'steerable'))
        loop.cycle.resolver_period.goal('world', np.array(GOOD_GOAL), 0.0)
        for _ in range(3):
            moving = loop.step()
        assert moving.command is not None and np.any(moving.arm_velocity)
        for bad, sends in ((loop._arm[:1], ['steer', 'drive']), (slice(None), [])):
            sent = []
            monkeypatch.setattr(world, 'set_command', lambda group, values, sent=sent: sent.append(group))
            names, q, qd = world.joint_state()
            q[bad] = NAN
            monkeypatch.setattr(world, 'joint_state', lambda names=names, q=q, qd=qd: (names, q, qd))
            t = world.time
            refused = loop.step()
            assert world.time > t and sent == sends and refused.command is None
            np.testing.assert_array_equal(refused.arm_velocity, moving.arm_velocity)  # still in force
            assert loop.events[-1].kind == 'joint_states rejected' and 'non-finite' in loop.events[-1].message
            monkeypatch.undo()
            moving = loop.step()
            assert moving.command is not None
    finally:
        world.close()
