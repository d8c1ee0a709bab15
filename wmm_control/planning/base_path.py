"""The way there: a base path clear of the obstacles, planned with OMPL (the ``ompl`` wheel).

The state is the base pose (x, y, θ); the robot drives with its arm held in the travel posture
(:class:`~wmm_control.planning.clearance.Travel`). The space follows what the base can do
(:attr:`~wmm_control.robot_config.BaseSection.path_turning_radius`):

* a base that moves sideways (steerable, Mecanum) moves in SE(2): between two states (x, y)
  along the straight line while θ turns the short way, at once;
* one that cannot (differential) moves on Reeds–Shepp curves (forward and backward, arcs of
  radius ρ and straight lines): ρ = v_max / ω_max, the radius at which it turns at full speed
  on both limits (0.25 m for ``panda_diff``); the base follows such a curve exactly, without
  sliding sideways.

A state is valid when the robot is ``margin + step`` clear of every obstacle; a motion between two
states is checked by conservative advancement (:meth:`Travel.motion_valid`): every pose along it,
not only the checked ones, keeps ``margin``. A robot that starts nearer an obstacle than that (a
reactive controller may have stopped it there) first takes a way out: the nearest valid pose
within 0.5 m (heading kept) that a motion reaches without coming nearer than it was, less
``step``, or, when there is none (held between two obstacles, or a differential base that cannot
back out straight), one within 1 m whose motion also turns the heading (by up to π); the path then
starts with that motion. A straight motion from start to goal is tried
first and, if valid, is the path. Else RRT-Connect searches ``attempts`` (4) times, each
shortened by OMPL's path simplifier (vertex reduction, again after every segment is cut in eight
so that corners can be cut, then close vertices collapsed; with the same checks), and the
shortest is kept. A search ends when it finds a path or after ``iterations`` (200) iterations of
its loop (one sample drawn, the trees extended towards it and joined); one that ends without a
path ends the searches (the paths found before it kept). Every search runs: the number of
searches, and so the path kept, does not depend on how fast the machine is. The wall-clock
``budget`` is only a safety cap on each search: one that reaches it before its iterations ends
the plan as :attr:`~wmm_control.planning.outcome.NoWay.TIMED_OUT`, with no path rather than one
the machine's speed chose. (Before, the four searches shared one 2 s budget, counted with the
simplifications, and the searches that did not fit in it were not made: on a loaded machine,
or in a node's thread beside the control loop, fewer searches ran and the path was longer, and
differed from run to run.) A ``table_pillar`` search takes 1–15 iterations, ``doorway`` and
``clutter`` up to 90 (the shipped robots, 6–10 goals each); a robot walled in fails its 200 in
about 1–3 s (``steerable``, ``panda_diff``, the machine loaded). The whole plan of a
``table_pillar`` goal (stance search, searches, simplifications; ``benchmarks/bench_planning.py
--goals 10``, both versions side by side on a loaded 2-core machine, load 4–6), median / p99 /
max [s], with the shared budget → every search: ``mecanum`` 4.3 / 5.4 / 5.4 → 7.2 / 9.1 / 9.1,
``panda_diff`` 5.1 / 8.3 / 8.3 → 14.7 / 22.2 / 22.6, ``steerable`` 3.8 / 6.4 / 6.4 → 10.4 / 15.1
/ 15.1, ``ur_mecanum`` 3.5 / 4.1 / 4.1 → 6.2 / 9.6 / 9.7; the trajectories' median duration
69.9 → 49.7 s, 16.5 → 13.4 s, 10.7 → 8.0 s, 21.9 → 14.6 s (the searches dropped before were the
ones that found shorter paths). Most of a plan's time is the simplification's motion checks.

A path longer than ``DETOUR_RATIO`` (2) times the straight way between its ends plus
``DETOUR_SLACK`` (2 m) is a detour (going round a wall's end, not round a table: every first
plan of ``table_pillar``'s goals, up to 7.5 m, is none): the planner searches again with ``narrow_margin`` (0.07 m;
0 turns this off) in place of the travel margin, and keeps that path where it is ``NARROW_GAIN``
(a quarter) shorter or more. A doorway whose lane at the travel margin is a few centimetres wide
(robot A in ``doorway``: every plan went round a wall's end) is found so; 0.07 m is above what
the safety stage holds a lagging base's body to (0.05 m). A robot that starts where the travel
margin has no way out (:attr:`~wmm_control.planning.outcome.NoWay.START_BLOCKED`; stopped in such
a gap, no pose within reach keeps the travel margin) is planned for with the narrow margin too,
and that path is kept where there is one.

Reproducible: OMPL draws the seed of every random generator it makes from one sequence,
which :func:`ompl.util.RNG.setSeed` restarts; each plan makes its planners and simplifiers anew
after restarting it with ``seed``, so the same query with the same seed gives the same path,
whatever the machine's speed (within the budget). The sequence is one per
process: plans in two threads at once are not reproducible.

:meth:`BasePathPlanner.plan` gives a :class:`BasePath`: the simplified waypoints and the path as
pieces the base follows one after the other (:mod:`~wmm_control.planning.timing`): one
:class:`~wmm_control.planning.timing.LinearPiece` per pair of waypoints in SE(2), and for
Reeds–Shepp the arcs and straight lines of each curve, each a
:class:`~wmm_control.planning.timing.TwistPiece` (split where the curvature or the direction of
travel changes).
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from ompl import base as ob
from ompl import geometric as og
from ompl import util as ou

from wmm_control.checks import as_finite_vector
from wmm_control.geometry import se2_twist, wrap_angle
from wmm_control.kinematics.obstacles import Obstacle
from wmm_control.planning.clearance import Travel
from wmm_control.planning.outcome import NoWay
from wmm_control.planning.timing import LinearPiece, Piece, TwistPiece
from wmm_control.robot_config import BaseSection

__all__ = ['BasePath', 'BasePathPlanner']

#: [m] added around the start, the goal, the obstacles and the robot for the sampled region
PADDING = 1.0
#: relative tolerance on a Reeds–Shepp stretch's twist per metre: (±1, 0, 0 or ±1/ρ)
_RS_PURE = 1e-7
#: [m] stretches shorter than this at a Reeds–Shepp junction are not split further
_RS_SPLIT = 1e-9
#: RRT-Connect searches of one plan (module docstring)
ATTEMPTS = 4
#: [m] the clearance a path may keep where one with the travel margin is a detour (module docstring)
NARROW_MARGIN = 0.07
#: a path longer than this many times the straight way between its ends, plus ``DETOUR_SLACK``
#: [m], is a detour, and one with ``NARROW_MARGIN`` that is shorter by ``NARROW_GAIN`` replaces it
DETOUR_RATIO = 2.0
DETOUR_SLACK = 2.0
NARROW_GAIN = 0.25
#: the most iterations of one RRT-Connect search (module docstring)
ITERATIONS = 200
#: [s] the safety cap on one search's wall time (module docstring)
BUDGET = 5.0
#: [m] how far a robot that starts nearer an obstacle than the margin looks for a way out, nearest first
ESCAPE = (0.1, 0.2, 0.35, 0.5)
#: directions of the way out, evenly spread
ESCAPE_BEARINGS = 16
#: when no straight way out keeps the heading: the turns [rad] a way out may make as it goes
#: (a robot held between two obstacles, or a differential base that cannot back out straight),
#: and how far it then looks [m]
ESCAPE_TURNS = (math.pi / 4, -math.pi / 4, math.pi / 2, -math.pi / 2, math.pi)
ESCAPE_TURNING = (*ESCAPE, 0.75, 1.0)


@dataclass(frozen=True)
class BasePath:
    """A planned base path, or why there is none.

    Attributes:
        waypoints: (x, y, θ) [m, m, rad], start first, goal last; empty when none. Shape (N, 3).
        pieces: the motions the base follows from one to the next (module docstring).
        no_way: the kind of reason when there is no path, else None.
        reason: a sentence for a log ('' when found).
        planning_time: [s] wall time of the whole plan (search and simplification).
        planner: 'direct' (the straight motion was valid), or OMPL's planner's name.
    """

    waypoints: np.ndarray
    pieces: tuple[Piece, ...]
    no_way: NoWay | None
    reason: str
    planning_time: float
    planner: str

    @property
    def found(self) -> bool:
        """Whether there is a path."""
        return self.no_way is None

    @property
    def length(self) -> float:
        """[m] the length of the polyline through the waypoints' positions (the way the base
        drives in SE(2); a lower bound of a Reeds–Shepp path's)."""
        return float(np.linalg.norm(np.diff(self.waypoints[:, :2], axis=0), axis=1).sum())

    @property
    def detour(self) -> bool:
        """Whether the path is a detour: longer than ``DETOUR_RATIO`` times the straight way
        between its ends plus ``DETOUR_SLACK`` (module docstring). No path is none."""
        if not self.found:
            return False
        straight = float(np.linalg.norm(self.waypoints[-1, :2] - self.waypoints[0, :2]))
        return self.length > DETOUR_RATIO * straight + DETOUR_SLACK

    @classmethod
    def none(cls, kind: NoWay, reason: str, began: float, planner: str = '') -> BasePath:
        """No path, for ``reason``, of a plan begun at ``began`` (``time.perf_counter()``)."""
        return cls(np.empty((0, 3)), (), kind, reason, time.perf_counter() - began, planner)


def _pose(state) -> tuple[float, float, float]:
    return (state.getX(), state.getY(), state.getYaw())


def _set(state, pose: Sequence[float] | np.ndarray) -> None:
    state.setX(float(pose[0]))
    state.setY(float(pose[1]))
    state.setYaw(wrap_angle(float(pose[2])))


class _Motions(ob.MotionValidator):
    """OMPL's motion check on :meth:`Travel.motion_valid`, along the space's own interpolation."""

    def __init__(self, si, space, travel: Travel, reeds_shepp_radius: float | None) -> None:
        super().__init__(si)
        # the space, not ``si``: ``si`` holds this validator, and a reference back to it from
        # Python would keep both alive for good
        self._space = space
        self._travel = travel
        self._rho = reeds_shepp_radius
        self._scratch = space.allocState()

    def sweep(self, a, b) -> float:
        """[m] how far any point of the robot moves, at most, per unit of the interpolation."""
        if self._rho is None:
            return self._travel.linear_sweep(_pose(a), _pose(b))
        return self._space.distance(a, b) * (1.0 + self._travel.radius / self._rho)

    def checkMotion(self, a, b) -> bool:  # noqa: N802 (OMPL's name)
        return self.valid(self._travel, a, b)

    def valid(self, travel: Travel, a, b) -> bool:
        """Whether the motion from ``a`` to ``b`` keeps ``travel``'s margin all along."""
        space, scratch = self._space, self._scratch

        def pose_at(lam: float) -> tuple[float, float, float]:
            space.interpolate(a, b, lam, scratch)
            return _pose(scratch)

        return travel.motion_valid(pose_at, self.sweep(a, b))


class _Search:
    """The termination condition of one RRT-Connect search (OMPL calls it once per iteration of
    its loop, before the iteration): the search ends after ``iterations`` iterations, or, as a
    safety cap on a machine too slow or loaded for them, once ``budget`` [s] have passed since it
    began (:attr:`timed_out`)."""

    def __init__(self, iterations: int, budget: float) -> None:
        self.iterations = iterations
        self.deadline = time.perf_counter() + budget
        self.count = 0
        self.timed_out = False

    def __call__(self) -> bool:
        if self.count >= self.iterations:
            return True
        if time.perf_counter() > self.deadline:
            self.timed_out = True
            return True
        self.count += 1
        return False


class BasePathPlanner:
    """Base paths among the obstacles for one robot (module docstring).

    Args:
        base: the robot's base section: its :attr:`~wmm_control.robot_config.BaseSection.path_turning_radius`
            chooses the space (and ρ).
        travel: the robot driving in its travel posture.
        budget: [s] the safety cap on each search's wall time: a search that reaches it
            (not its iterations) ends the plan with no path (module docstring).
        seed: > 0, OMPL's random seed for every plan.
        attempts: RRT-Connect searches (each simplified); the shortest path is kept.
        narrow_margin: [m] the clearance a path may keep instead of the travel margin where that
            one is a detour (module docstring); 0: the travel margin only.
        simplify_rounds: rounds of vertex reduction after each search.
        iterations: the most iterations of each search (one sample drawn and each tree
            extended towards it); a search that ends without a path ends the searches.
    """

    def __init__(
        self,
        base: BaseSection,
        travel: Travel,
        budget: float = BUDGET,
        seed: int = 1,
        attempts: int = ATTEMPTS,
        simplify_rounds: int = 15,
        iterations: int = ITERATIONS,
        narrow_margin: float = NARROW_MARGIN,
    ) -> None:
        if not budget > 0.0:
            raise ValueError(f'the time budget must be > 0 [s], got {budget}')
        if int(iterations) < 1 or int(attempts) < 1:
            raise ValueError(f'a plan needs at least one search of one iteration, got {attempts}, {iterations}')
        if int(seed) <= 0:
            raise ValueError(f'the seed must be > 0 (OMPL takes 0 for "random"), got {seed}')
        self.base = base
        self.travel = travel
        self.budget = float(budget)
        self.seed = int(seed)
        self.attempts = int(attempts)
        self.simplify_rounds = int(simplify_rounds)
        self.iterations = int(iterations)
        self.rho = base.path_turning_radius
        if not narrow_margin >= 0.0:
            raise ValueError(f'the narrow margin must be >= 0 [m], got {narrow_margin}')
        self.narrow_margin = float(narrow_margin)

    @property
    def least_margin(self) -> float:
        """[m] the least clearance a path of this planner keeps from the obstacles: the travel
        margin, or the narrow margin where it is smaller."""
        margin = self.travel.margin
        return min(margin, self.narrow_margin) if self.narrow_margin > 0.0 else margin

    def _space(self, start: np.ndarray, goal: np.ndarray, obstacles: Sequence[Obstacle]):
        space = ob.SE2StateSpace() if self.rho is None else ob.ReedsSheppStateSpace(self.rho)
        points = [start[:2], goal[:2]] + [o.position[:2] for o in obstacles]
        extent = max((float(max(o.size)) for o in obstacles), default=0.0)
        pad = PADDING + self.travel.radius + extent
        lo, hi = np.min(points, axis=0) - pad, np.max(points, axis=0) + pad
        bounds = ob.RealVectorBounds(2)
        for axis in range(2):
            bounds.setLow(axis, float(lo[axis]))
            bounds.setHigh(axis, float(hi[axis]))
        space.setBounds(bounds)
        return space

    def plan(self, start: Sequence[float] | np.ndarray, goal: Sequence[float] | np.ndarray) -> BasePath:
        """A path of the base from ``start`` to ``goal`` (x, y, θ in the world), or why none."""
        began = time.perf_counter()
        start = as_finite_vector(start, 3, 'start pose')
        goal = as_finite_vector(goal, 3, 'goal pose')
        travel = self.travel

        if np.array_equal(start, goal):  # there already: no motion to check
            return self._path([start, goal], None, began, 'direct')
        if not travel.valid(goal):
            return BasePath.none(
                NoWay.NO_PATH,
                f'the base at the stance would be {travel.obstacle_clearance(goal):.3f} m from an obstacle; '
                f'the path keeps {travel.margin + travel.step:g} m',
                began,
            )
        level = ou.getLogLevel()
        try:
            ou.setLogLevel(ou.LOG_NONE)
            path = self._plan(start, goal, began)
            if not 0.0 < self.narrow_margin < travel.margin:
                return path
            narrow = copy.copy(self)
            narrow.travel = travel.with_margin(self.narrow_margin)
            if path.no_way is NoWay.START_BLOCKED:
                # stopped in a gap the travel margin finds no way out of (nowhere within it keeps
                # that margin): the narrow margin may have one
                other = narrow._plan(start, goal, began)
                return other if other.found else path
            if not path.detour:
                return path
            # a detour: a way the travel margin leaves too narrow to find may be through a gap
            other = narrow._plan(start, goal, began)
            return other if other.found and other.length < (1.0 - NARROW_GAIN) * path.length else path
        finally:
            ou.setLogLevel(level)

    def _plan(self, start: np.ndarray, goal: np.ndarray, began: float) -> BasePath:
        space = self._space(start, goal, self.travel.clearance.obstacles)
        si = ob.SpaceInformation(space)
        si.setStateValidityChecker(lambda state: self.travel.valid(_pose(state)))
        motions = _Motions(si, space, self.travel, self.rho)
        si.setMotionValidator(motions)
        si.setup()
        a, b = space.allocState(), space.allocState()
        _set(a, start)
        _set(b, goal)
        before = []  # the way out, when the robot starts nearer an obstacle than the margin
        if not self.travel.valid(start):
            out = self._escape(space, motions, start)
            if out is None:
                return BasePath.none(
                    NoWay.START_BLOCKED,
                    f'the robot is {self.travel.obstacle_clearance(start):.3f} m from an obstacle where it '
                    f'stands, and no straight way out within {ESCAPE[-1]:g} m keeps that far',
                    began,
                )
            before, a = [a], out
        if motions.checkMotion(a, b):
            return self._path([*before, a, b], space, began, 'direct')
        ou.RNG.setSeed(self.seed)  # every generator made from here on: see the module docstring
        best: tuple[float, list] | None = None
        why = ''
        for _ in range(self.attempts):
            search = _Search(self.iterations, self.budget)
            pdef = ob.ProblemDefinition(si)
            pdef.setStartAndGoalStates(a, b)
            planner = og.RRTConnect(si)
            planner.setProblemDefinition(pdef)
            planner.setup()
            status = planner.solve(ob.PlannerTerminationCondition(search))
            if search.timed_out:  # the safety cap: no path rather than one the machine's speed chose
                return BasePath.none(
                    NoWay.TIMED_OUT,
                    f'a base path search took longer than its {self.budget:g} s budget '
                    f'(after {search.count} of at most {self.iterations} iterations)',
                    began,
                    'RRTConnect',
                )
            if status.getStatus() != ob.PlannerStatus.PlannerStatusType.EXACT_SOLUTION:
                why = f'in {self.iterations} iterations of a search ({status.asString()})'
                break
            path = pdef.getSolutionPath()
            self._simplify(og.PathSimplifier(si), path)
            if best is None or path.length() < best[0]:
                best = (path.length(), [_pose(path.getState(i)) for i in range(path.getStateCount())])
        if best is None:
            return BasePath.none(NoWay.NO_PATH, f'no base path found ({why})', began, 'RRTConnect')
        states = list(before)
        for pose in best[1]:
            state = space.allocState()
            _set(state, pose)
            states.append(state)
        return self._path(states, space, began, 'RRTConnect')

    def _escape(self, space, motions: _Motions, start: np.ndarray):
        """A state near ``start`` (which is not valid) that is valid and reached by a motion
        that keeps the start's clearance (less ``step``) all along: ``ESCAPE`` distances in
        ``ESCAPE_BEARINGS`` directions, heading kept, the nearest first and of those the
        clearest; when none, the same with the heading turned by each of ``ESCAPE_TURNS`` on
        the way, out to ``ESCAPE_TURNING``; None when there is none (or the robot is within
        ``step`` of an obstacle)."""
        travel = self.travel
        held = travel.obstacle_clearance(start) - travel.step
        if held <= 0.0:
            return None
        relaxed = travel.with_margin(held)
        a = space.allocState()
        _set(a, start)
        for turns, distances in (((0.0,), ESCAPE), (ESCAPE_TURNS, ESCAPE_TURNING)):
            for distance in distances:
                ways = []
                for k, turn in enumerate(turns):
                    for i in range(ESCAPE_BEARINGS):
                        bearing = 2.0 * math.pi * i / ESCAPE_BEARINGS
                        pose = start + np.array((distance * math.cos(bearing), distance * math.sin(bearing), turn))
                        pose[2] = wrap_angle(float(pose[2]))
                        d = travel.obstacle_clearance(pose)
                        if d >= travel.margin + travel.step:
                            b = space.allocState()
                            _set(b, pose)
                            if motions.valid(relaxed, a, b):
                                ways.append((d, -k, -i, b))
                if ways:
                    return max(ways, key=lambda way: way[:3])[3]
        return None

    def _simplify(self, simplifier, path) -> None:
        """Shorten ``path``: vertex reduction, then again with each segment cut in eight (so
        that corners can be cut, not only vertices skipped), then close vertices collapsed."""
        for _ in range(self.simplify_rounds):
            if not simplifier.reduceVertices(path):
                break
        for _ in range(3):
            path.subdivide()
        for _ in range(2 * self.simplify_rounds):
            if not simplifier.reduceVertices(path):
                break
        simplifier.collapseCloseVertices(path)

    def _path(self, states, space, began: float, planner: str) -> BasePath:
        """The path through ``states`` (OMPL states of ``space``; two equal poses without a space)."""
        if space is None:
            waypoints = np.array(states, dtype=float)
            piece = TwistPiece(waypoints[0], np.zeros(3))
            return BasePath(waypoints, (piece,), None, '', time.perf_counter() - began, planner)
        waypoints = np.array([_pose(s) for s in states])
        pieces: list[Piece] = []
        for a, b in zip(states[:-1], states[1:]):
            if self.rho is None:
                pieces.append(LinearPiece(np.array(_pose(a)), np.array(_pose(b))))
            else:
                pieces.extend(_reeds_shepp_pieces(space, a, b, self.rho))
        if not pieces:  # the base is there already
            pieces.append(TwistPiece(waypoints[0], np.zeros(3)))
        return BasePath(waypoints, tuple(pieces), None, '', time.perf_counter() - began, planner)


def _reeds_shepp_pieces(space, a, b, rho: float) -> list[TwistPiece]:
    """The arcs and straight lines of the Reeds–Shepp curve from ``a`` to ``b``, each a
    :class:`TwistPiece`: found by halving the curve until each part moves at one twist per metre
    (forward or backward; turning left, right or not), then joining equal neighbours."""
    length = space.distance(a, b)
    scratch = space.allocState()

    def pose_at(f: float) -> np.ndarray:
        space.interpolate(a, b, f, scratch)
        return np.array(_pose(scratch))

    def kind(f0: float, f1: float, p0: np.ndarray, p1: np.ndarray) -> tuple[int, int] | None:
        """(direction ±1, turn −1/0/1) of the part from f0 to f1, None if it is not one."""
        metres = (f1 - f0) * length
        twist = se2_twist(p0, p1, 1.0) / metres
        direction = 1 if twist[0] > 0.0 else -1
        turn = twist[2] * rho * direction
        nearest = round(turn)
        pure = abs(abs(twist[0]) - 1.0) + abs(twist[1]) + abs(turn - nearest) <= _RS_PURE
        return (direction, int(nearest)) if pure and abs(nearest) <= 1 else None

    parts: list[tuple[float, float, tuple[int, int]]] = []

    def split(f0: float, f1: float, p0: np.ndarray, p1: np.ndarray) -> None:
        if (f1 - f0) * length <= _RS_SPLIT:
            return
        found = kind(f0, f1, p0, p1)
        if found is not None:
            if parts and parts[-1][2] == found:  # (a gap between them is below _RS_SPLIT)
                parts[-1] = (parts[-1][0], f1, found)
            else:
                parts.append((f0, f1, found))
            return
        mid = 0.5 * (f0 + f1)
        pm = pose_at(mid)
        split(f0, mid, p0, pm)
        split(mid, f1, pm, p1)

    if length > 0.0:
        count = max(1, math.ceil(length / 0.05))
        marks = [i / count for i in range(count + 1)]
        poses = [pose_at(f) for f in marks]
        for i in range(count):
            split(marks[i], marks[i + 1], poses[i], poses[i + 1])
    pieces = []
    for f0, f1, (direction, turn) in parts:
        metres = (f1 - f0) * length
        twist = np.array((direction * metres, 0.0, direction * turn * metres / rho))
        pieces.append(TwistPiece(pose_at(f0), twist))
    return pieces
