"""One experiment run with every node in one process, talking over real topics.

The run has a ROS domain of its own (:func:`private_domain_id`). The simulator (``wmm_sim``, lockstep), the base controller (``swmr_controller`` for robot A,
``mecanum_controller`` for robot B),
the ``redundancy_resolver`` and the ``goal_sequencer`` run on one executor with a private
rclpy context, exactly as they run as separate processes; with ``planner``, ``goal_planner``
too, between the sequencer's ``/goal_pose`` and the resolver, as ``robot.launch.py planner:=true``
wires it. A recorder node listens to the
topics a user would watch (ground-truth end-effector pose and base pose, joint states,
feasible twist), takes each resolver cycle from the resolver node (in this process, exact),
and fills a :class:`~wmm_control.experiments.metrics.RunLog`, one row per control period.
"""

import os
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import rclpy
from geometry_msgs.msg import PoseStamped, TwistStamped
from nav_msgs.msg import Odometry
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState

from sim_bridge.node import SimNode
from wmm_control.errors import ConfigError
from wmm_control.experiments.metrics import RunLog
from wmm_control.experiments.recording import BagRecorder
from wmm_control.experiments.scenario import Scenario, resolver_parameters
from wmm_control.nodes.conversions import odometry_pose, planar_twist, pose_rotation
from wmm_control.nodes.goal_planner import GoalPlannerNode
from wmm_control.nodes.goal_sequencer import GoalSequencerNode
from wmm_control.nodes.base_controller import BaseControllerNode
from wmm_control.nodes.redundancy_resolver import RedundancyResolverNode
from wmm_control.resolvers.interface import ResolverCommand
from wmm_control.robot_config import RobotConfig, load_robot

__all__ = ['run_with_nodes', 'Recorder', 'private_domain_id', 'LOCKSTEP_TIMEOUT']


class Recorder(Node):
    """Collects, per control period (the stamp of its joint state), the ground truth and the
    resolver's cycle, and turns them into RunLog rows.

    Every message it uses carries the stamp of the period it belongs to, so the rows do not
    depend on the order in which the topics are delivered: ``/ee_pose`` and
    ``/ground_truth/odom`` (the true state), ``/joint_states`` and ``/base/feasible_twist``. The
    resolver's cycle (the commands it sent, ψ, mode, scales, the goal's state) comes from the
    resolver node in this process (:meth:`observe`, one of its ``cycle_observers``), exact and
    without a ``/diagnostics`` message every period.

    ``towards_goal`` (default: always) tells whether the resolver's target is the user's goal; the
    goal's state (reached, stalled) is taken only then: with ``goal_planner`` the resolver tracks a
    plan's points, or holds the robot while a plan is made, before the goal is handed over.
    """

    def __init__(
        self,
        context: rclpy.Context,
        robot: RobotConfig,
        scenario: Scenario,
        log: RunLog,
        towards_goal: Callable[[], bool] | None = None,
    ) -> None:
        super().__init__('experiment_recorder', context=context)
        self.scenario = scenario
        self.log = log
        self.towards_goal = towards_goal
        self.arm_joints = robot.arm.joints
        self._index = None
        self._rows: dict[tuple[int, int], dict[str, Any]] = {}
        self.last_t = -1.0
        self.final_status: dict | None = None
        self.first_stall_s: float | None = None
        self.create_subscription(PoseStamped, '/ee_pose', self._on_ee, 10)
        self.create_subscription(Odometry, '/ground_truth/odom', self._on_base, 10)
        self.create_subscription(JointState, '/joint_states', self._on_joints, 10)
        self.create_subscription(TwistStamped, '/base/feasible_twist', self._on_feasible, 10)

    def _row(self, stamp):
        key = (stamp.sec, stamp.nanosec)
        return self._rows.setdefault(key, {'t': stamp.sec + stamp.nanosec * 1e-9})

    def _on_ee(self, msg):
        self._row(msg.header.stamp)['ee'] = pose_rotation(msg.pose)

    def _on_base(self, msg):
        self._row(msg.header.stamp)['base'] = odometry_pose(msg)[0]

    def _on_joints(self, msg):
        if self._index is None:
            names = list(msg.name)
            self._index = [names.index(j) for j in self.arm_joints]
            self.log.joint_names = tuple(names)
        row = self._row(msg.header.stamp)
        row['q'] = np.asarray(msg.position, dtype=float)
        row['q_arm'] = row['q'][self._index]
        self.last_t = max(self.last_t, row['t'])

    def _on_feasible(self, msg):
        self._row(msg.header.stamp)['feasible'] = planar_twist(msg.twist)

    def observe(self, stamp: tuple[int, int], command: ResolverCommand, reached: bool, stalled: bool) -> None:
        """The resolver's cycle stamped ``stamp`` (see ``RedundancyResolverNode.cycle_observers``)."""
        row = self._row(stamp)
        row['command'] = command
        if self.towards_goal is not None and not self.towards_goal():
            reached = stalled = False
        self.final_status = {'goal_reached': bool(reached), 'goal_stalled': bool(stalled)}
        if self.first_stall_s is None and stalled:
            self.first_stall_s = row['t']

    def flush(self) -> None:
        """Append every complete row (a period in which a goal was pursued), in time order."""
        for key in sorted(self._rows):
            row = self._rows[key]
            if not all(k in row for k in ('command', 'ee', 'base', 'q_arm')):
                continue
            command = row['command']
            self.log.append(
                row['t'],
                self.scenario.goal_index(row['t']),
                row['ee'][0],
                row['ee'][1],
                row['base'],
                row['q_arm'],
                command.arm_velocity,
                command.base_twist,
                row.get('feasible'),
                command.diagnostics,
                q=row['q'],
            )
        self._rows.clear()


def _executor(context):
    try:
        from rclpy.experimental import EventsExecutor

        return EventsExecutor(context=context)
    except ImportError:
        return SingleThreadedExecutor(context=context)


#: [s] the wall time the simulator waits, in lockstep, for the commands that answer a state before
#: it steps anyway. The other nodes learn it (``sim/lockstep_timeout``,
#: :mod:`~wmm_control.nodes.sim_timing`): they age their inputs by the simulated time, answer every
#: state however long it waited, wait for each other's answers as long as the simulator waits,
#: and stop only when no state comes for their timeout plus this. Far beyond any period, so that
#: the run does not depend on timing, also when other processes (the runs of ``wmm_experiment
#: --jobs``) take the cores.
LOCKSTEP_TIMEOUT = 10.0


def private_domain_id(offset: int = 0) -> int:
    """A ROS domain for this process alone (101–200, from the process id), so that an experiment
    never hears, nor drives, a robot system running on the machine's usual domain. ``offset``
    gives the process's worker runs domains of their own: offsets 1, 2, … are other domains,
    up to a hundred of them."""
    return 101 + (os.getpid() + offset) % 100


def run_with_nodes(
    scenario: Scenario,
    run: Mapping[str, Any],
    progress: Callable[[float], object] | None = None,
    wall_timeout: float | None = None,
    domain_id: int | None = None,
    bag_path: str | Path | None = None,
    view_port: int | None = None,
    planner: bool = False,
    after_plan: bool = False,
) -> RunLog:
    """Run one entry of ``scenario.runs`` with every node in this process.

    Args:
        scenario: a :class:`~wmm_control.experiments.scenario.Scenario`.
        run: one of its runs (``name``, ``method``, ``feedback``, resolver parameters).
        progress: optional callable ``progress(simulated_seconds)`` called as the run advances.
        wall_timeout: give up after this many wall seconds (default: ten times the duration).
        domain_id: ROS domain of the run; default :func:`private_domain_id`.
        bag_path: a rosbag2 folder (MCAP) to record every topic of the run into
            (:class:`~wmm_control.experiments.recording.BagRecorder`), the resolver's
            ``/diagnostics`` every period among them; None records nothing.
        view_port: serve the live browser view of the run (``wmm_viewer``) on this HTTP port;
            None: no viewer.
        planner: run ``goal_planner`` between the goals and the resolver (the scenario's
            obstacles, the run's odometry); the goal counts as reached or stalled only once the
            planner has handed it to the resolver, and ``planning`` holds the planner's account.
        after_plan: with ``planner``, the scenario's duration counts from when the base path of
            the goal's first plan is planned to end, as
            :func:`~wmm_control.experiments.direct.run_scenario`'s ``after_plan``.

    Returns:
        The frozen :class:`RunLog` (``wall_time_s`` set).

    Raises:
        ConfigError: a bad run entry, or the run stalled (no progress for ``wall_timeout``).
    """
    robot = load_robot(scenario.robot)
    feedback = run.get('feedback', 'ground_truth')
    if feedback not in ('ground_truth', 'odometry'):
        raise ConfigError(f'run {run.get("name")}: feedback must be ground_truth or odometry, got {feedback!r}')
    resolver_params = dict(resolver_parameters(run), method=run['method'])
    # No ~/markers: they are for rviz, on a steady-clock timer, and would not repeat from run to run.
    resolver_params.update(
        robot=str(robot.yaml_path),
        ee_feedback=feedback,
        markers_period=0.0,
    )
    if bag_path is not None:  # the bag gets every cycle's report (ψ, mode, scales) for offline analysis
        resolver_params['diagnostics_period'] = 1e-9
    sim_params = dict(scenario.sim or {})
    sim_params.update(
        robot=str(robot.yaml_path), timing='lockstep', diagnostics_period=0.0, lockstep_timeout=LOCKSTEP_TIMEOUT
    )
    if scenario.obstacles_file:
        sim_params['obstacles'] = resolver_params['obstacles'] = scenario.obstacles_file
    for key in ('slip_drift', 'slip_noise'):
        if key in sim_params:
            sim_params[key] = [float(v) for v in sim_params[key]]
    if 'slip_gain' in sim_params:
        sim_params['slip_gain'] = float(sim_params['slip_gain'])

    def params(values: Mapping[str, Any]) -> list[Parameter]:
        return [Parameter(k, value=v) for k, v in values.items()]

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=private_domain_id() if domain_id is None else domain_id)
    log = RunLog(method=run['method'], label=run['name'])
    nodes: list[Node] = []
    executor = _executor(context)
    try:
        remap = ['-r', '/odom:=/ground_truth/odom'] if feedback == 'ground_truth' else []
        nodes.append(
            GoalSequencerNode(
                context=context, parameter_overrides=params({'scenario': str(scenario.path), 'use_sim_time': True})
            )
        )
        goal_planner = None
        if planner:  # as robot.launch.py planner:=true: the user's goals go to the planner
            goal_planner = GoalPlannerNode(
                context=context,
                cli_args=['--ros-args', *remap],
                parameter_overrides=params(
                    {'robot': str(robot.yaml_path), 'obstacles': scenario.obstacles_file, 'diagnostics_period': 0.0}
                ),
            )
            nodes.append(goal_planner)
            remap = [*remap, '-r', 'goal_pose:=goal_planner/goal']
        resolver = RedundancyResolverNode(
            context=context, cli_args=['--ros-args', *remap], parameter_overrides=params(resolver_params)
        )
        nodes.append(resolver)
        nodes.append(
            BaseControllerNode(
                robot.base.family,
                context=context,
                parameter_overrides=params({'robot': str(robot.yaml_path)}),
            )
        )
        recorder = Recorder(
            context, robot, scenario, log, None if goal_planner is None else lambda: goal_planner.pursuit.goal_handed
        )
        resolver.cycle_observers.append(recorder.observe)
        nodes.append(recorder)
        sim = SimNode(context=context, parameter_overrides=params(sim_params))
        nodes.append(sim)
        bag = None
        if bag_path is not None:
            bag = BagRecorder(context, bag_path)
            nodes.append(bag)
            bag.subscribe_all()
        if view_port is not None:
            # viser (the browser viewer) is imported only by runs that show themselves live
            from wmm_control.nodes.viewer import ViewerNode

            nodes.append(
                ViewerNode(
                    context=context, parameter_overrides=params({'robot': str(robot.yaml_path), 'port': int(view_port)})
                )
            )
        for node in nodes:
            executor.add_node(node)
        limit = wall_timeout if wall_timeout is not None else 10.0 * scenario.duration + 30.0
        start = time.perf_counter()
        reported = 0.0

        def length() -> float:  # [s] asked each time round (a plan may lengthen the run)
            if after_plan and goal_planner is not None:
                return goal_planner.pursuit.limit(scenario.duration)
            return scenario.duration

        while recorder.last_t + 1e-9 < length():
            executor.spin_once(timeout_sec=0.1)
            if progress is not None and recorder.last_t > reported:
                progress(recorder.last_t - reported)
                reported = recorder.last_t
            if time.perf_counter() - start > limit:
                raise ConfigError(
                    f'run {run["name"]}: no progress after {limit:.0f} s wall time (sim time {recorder.last_t:.3f} s)'
                )
        recorder.flush()
        if bag is not None:
            bag.close()
        log.wall_time_s = time.perf_counter() - start
        log.final_status = recorder.final_status
        log.first_stall_s = recorder.first_stall_s
        log.sim_counters = {g: dict(c) for g, c in sim.world.counters.items()}  # what /diagnostics reports
        log.safety_counts = resolver.period.safety_counts.values()  # what the resolver's /diagnostics reports
        if goal_planner is not None:
            log.planning = goal_planner.pursuit.account()
    finally:
        for node in nodes:
            executor.remove_node(node)
            node.destroy_node()
        executor.shutdown()
        rclpy.try_shutdown(context=context)
    return log.freeze()
