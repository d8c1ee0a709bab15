"""A whole scenario played on the direct engine: a :class:`~sim_bridge.closed_loop.ClosedLoop`
on a :class:`~sim_bridge.world.SimWorld`, no ROS in between, logged as a
:class:`~wmm_control.experiments.metrics.RunLog`."""

import time
from collections.abc import Callable, Iterable, Sequence

import numpy as np
from sim_bridge.closed_loop import ClosedLoop
from sim_bridge.world import SimWorld
from wmm_control.cycle import steady_heap
from wmm_control.errors import ConfigError
from wmm_control.experiments.metrics import RunLog
from wmm_control.experiments.scenario import Scenario
from wmm_control.geometry import quaternion_from_matrix
from wmm_control.kinematics.obstacles import Obstacle
from wmm_control.planning.pursuit import GoalPursuit, PursuitState
from wmm_control.resolvers.interface import Resolver, ResolverDiagnostics

__all__ = ['run_scenario']


def run_scenario(
    world: SimWorld,
    resolver: Resolver,
    scenario: Scenario,
    feedback: str = 'ground_truth',
    label: str = '',
    progress: Callable[[int], object] | None = None,
    until: Callable[[ResolverDiagnostics], bool] | None = None,
    pursuit: GoalPursuit | None = None,
    obstacle_changes: Sequence[tuple[float, Iterable[Obstacle]]] = (),
    after_plan: bool = False,
) -> RunLog:
    """Run a whole scenario (goals or a trajectory) on ``world`` with no ROS in between.

    Args:
        world: a fresh :class:`~sim_bridge.world.SimWorld` of the scenario's robot.
        resolver: the method under test.
        scenario: a :class:`~wmm_control.experiments.scenario.Scenario`.
        feedback: see :class:`~sim_bridge.closed_loop.ClosedLoop`.
        label: name of the run in the log.
        progress: optional callable ``progress(n_periods)`` called after each period.
        until: optional callable ``until(diagnostics)``, given each period's
            :class:`~wmm_control.resolvers.ResolverDiagnostics` towards the scenario's goals
            (not those of a plan's points): the run ends early when it returns True.
        pursuit: the scenario's goals pursued past what is in the way, as ``goal_planner``
            does (:class:`~wmm_control.planning.pursuit.GoalPursuit`, best made with
            ``threaded=False``): each goal is given to it when its time comes, and each period
            what it sends (a plan's point, the goal, a hold) goes to the cycle; the run ends when
            it finds no way to the last goal. A plan given to it first
            (:meth:`~wmm_control.planning.pursuit.GoalPursuit.follow_plan`) is followed from the start.
        obstacle_changes: ``(t, obstacles)`` pairs: from ``t`` [s] on, the obstacles are these,
            in the world, in the cycle and for the pursuit (an obstacle that moves).
        after_plan: with ``pursuit``, the scenario's duration counts from when the base path of
            the goal's first plan is planned to end
            (:meth:`~wmm_control.planning.pursuit.GoalPursuit.limit`): the run lasts that much
            longer; without, it lasts the scenario's duration.

    Returns:
        The frozen :class:`~wmm_control.experiments.metrics.RunLog`.
    """
    if pursuit is not None and scenario.trajectory is not None:
        raise ConfigError('a pursuit takes goals, not a trajectory: give the scenario goals')
    # the scenario's obstacles, in the world and in the controller's collision model
    world.set_obstacles(scenario.obstacles)
    loop = ClosedLoop(world, resolver, feedback=feedback)
    loop.set_obstacles(scenario.obstacles)
    changes = sorted(((float(t), tuple(obstacles)) for t, obstacles in obstacle_changes), key=lambda c: c[0])
    log = RunLog(method=resolver.name, label=label, joint_names=world.joint_names)
    reference = scenario.reference(resolver.model) if scenario.trajectory is not None else None

    def periods() -> int:  # the run's length in periods, asked each period (a plan may lengthen it)
        length = pursuit.limit(scenario.duration) if after_plan and pursuit is not None else scenario.duration
        return int(round(length / world.dt))

    t0 = time.perf_counter()
    submitted = None
    done = 0
    with steady_heap():  # no full pass of the garbage collector walks the models mid-run
        while done < periods():
            done += 1
            while changes and changes[0][0] <= world.time + 1e-9:
                obstacles = changes.pop(0)[1]
                world.set_obstacles(obstacles)
                loop.set_obstacles(obstacles)
                if pursuit is not None:
                    pursuit.set_obstacles(obstacles)
            gi = scenario.goal_index(world.time)
            towards_goal = True  # the diagnostics are towards the scenario's goal (not a plan's point)
            if pursuit is not None:
                if gi != submitted:
                    goal = scenario.target(world.time, reference)
                    pose = np.concatenate((goal.position, quaternion_from_matrix(goal.rotation)))
                    pursuit.new_goal(loop.world_frame, pose)
                    submitted = gi
                if pursuit.state is PursuitState.NO_WAY and gi == len(scenario.goals) - 1:
                    break  # no way to the last goal
                state = loop.state()
                step = pursuit.step(world.dt, state.base_pose, state.q_arm)
                if step.reference is not None:  # a plan's point, or its final approach's goal
                    rec = loop.step(step.reference, tracking=True)
                elif step.forward_goal:
                    rec = loop.step(pursuit.goal, tracking=False)
                else:
                    rec = loop.step(step.hold, tracking=False)
                towards_goal = pursuit.state in (PursuitState.APPROACH, PursuitState.DIRECT)
            elif reference is not None:  # a trajectory: a point every period, as goal_sequencer publishes it
                rec = loop.step(scenario.target(world.time, reference), tracking=True)
            else:  # goals: each when its time comes, as goal_sequencer publishes them
                rec = loop.step(scenario.target(world.time, reference) if gi != submitted else None, tracking=False)
                submitted = gi
            cmd = rec.command
            if cmd is None:  # the target was refused (loop.events say why): the robot held, as the
                # resolver node holds it, and nothing logged, as the node's recorder logs nothing
                if progress is not None:
                    progress(1)
                continue
            log.append(
                rec.t,
                gi,
                rec.ee_position,
                rec.ee_rotation,
                rec.base_pose,
                rec.q_arm,
                cmd.arm_velocity,
                cmd.base_twist,
                rec.feasible_twist,
                cmd.diagnostics,
                q=rec.q,
                cycle_s=rec.cycle_s,
                cycle_cpu_s=rec.cycle_cpu_s,
            )
            if progress is not None:
                progress(1)
            if until is not None and towards_goal and until(cmd.diagnostics):
                break
    log.wall_time_s = time.perf_counter() - t0
    refusals = [e.message for e in loop.events if e.kind == 'rejected']
    log.refused = refusals[-1] if refusals else ''
    log.sim_counters = {g: dict(c) for g, c in world.counters.items()}
    # the cycles in which each limit of the safety stage shaped the command, as the resolver node's /diagnostics
    log.safety_counts = loop.cycle.resolver_period.safety_counts.values()
    return log.freeze()
