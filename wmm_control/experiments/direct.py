"""A whole scenario played on the direct engine: a :class:`~sim_bridge.closed_loop.ClosedLoop`
on a :class:`~sim_bridge.world.SimWorld`, no ROS in between, logged as a
:class:`~wmm_control.experiments.metrics.RunLog`."""

import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np
from sim_bridge.closed_loop import ClosedLoop
from sim_bridge.world import SimWorld
from wmm_control.cycle import steady_heap
from wmm_control.experiments.metrics import RunLog
from wmm_control.experiments.scenario import Scenario
from wmm_control.planning.follow import MAX_REPLANS, FollowState, PlanFollower
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
    follower: PlanFollower | None = None,
    replan: Callable[[np.ndarray, np.ndarray], PlanFollower | None] | None = None,
    max_replans: int = MAX_REPLANS,
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
        follower: a plan to follow first (:class:`~wmm_control.planning.follow.PlanFollower`):
            its point every period, at the pace of the measured base and end effector, from the
            start; the scenario's goals once it is in its final approach, with the plan's
            last base pose held (:attr:`~wmm_control.planning.follow.PlanFollower.approach`).
        replan: with ``follower``, ``replan(base_pose, q_arm)``, called when the follower
            stalls, with the measured base pose (x, y, θ) and arm joints: the follower of a new
            plan from there, or None when there is none (the run ends).
        max_replans: the most calls of ``replan`` in a run; when the follower stalls after them
            the scenario's goals are given from where the robot is (the method's own approach,
            judged as without a plan).

    Returns:
        The frozen :class:`~wmm_control.experiments.metrics.RunLog`.
    """
    # the scenario's obstacles, in the world and in the controller's collision model
    world.set_obstacles(scenario.obstacles)
    loop = ClosedLoop(world, resolver, feedback=feedback)
    loop.set_obstacles(scenario.obstacles)
    log = RunLog(method=resolver.name, label=label, joint_names=world.joint_names)
    reference = scenario.reference(resolver.model) if scenario.trajectory is not None else None
    n = int(round(scenario.duration / world.dt))
    t0 = time.perf_counter()
    submitted = None
    replans = 0
    approach_base = None
    with steady_heap():  # no full pass of the garbage collector walks the models mid-run
        for _ in range(n):
            gi = scenario.goal_index(world.time)
            following = None
            if follower is not None:  # the planned way there first, as /ee_reference points
                state = loop.state()
                pose = state.base_pose
                ee_position, ee_rotation = state.ee_placement(resolver.model, update=True)
                following = follower.step(world.dt, pose, ee_position, ee_rotation)
                if following.state is FollowState.STALLED and replan is not None:
                    if replans >= max_replans:  # no more plans: the goal from where the robot is
                        following = None
                    else:
                        replans += 1
                        follower = replan(pose, state.q_arm)
                        if follower is None:  # no way from here
                            break
                        following = follower.step(0.0, pose)
                if following is not None and following.state is FollowState.APPROACH:
                    approach_base = following.target.base  # the stance held in the final approach
                if following is None or following.state is FollowState.APPROACH:
                    follower = following = None
            if following is not None:
                rec = loop.step(following.target, tracking=True)
            elif reference is not None:  # a trajectory: a point every period, as goal_sequencer publishes it
                rec = loop.step(scenario.target(world.time, reference), tracking=True)
            else:  # goals: each when its time comes, as goal_sequencer publishes them
                goal = None
                if gi != submitted:
                    goal = scenario.target(world.time, reference)
                    if approach_base is not None:  # after a plan: its approach holds the stance
                        goal = replace(goal, base=approach_base)
                rec = loop.step(goal, tracking=False)
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
            if until is not None and following is None and until(cmd.diagnostics):
                break
    log.wall_time_s = time.perf_counter() - t0
    refusals = [e.message for e in loop.events if e.kind == 'rejected']
    log.refused = refusals[-1] if refusals else ''
    log.sim_counters = {g: dict(c) for g, c in world.counters.items()}
    # the cycles in which each limit of the safety stage shaped the command, as the resolver node's /diagnostics
    log.safety_counts = loop.cycle.resolver_period.safety_counts.values()
    return log.freeze()
