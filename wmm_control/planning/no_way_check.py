"""Whether the planner's "no way" is right: a check apart from the search that gave it.

:func:`confirm_no_way` takes the planner's verdict for a goal (its
:class:`~wmm_control.planning.outcome.NoWay` kind) and answers *confirmed* (the check shows
there is none, within what it says it covers), *refuted* (it found what the planner missed:
a stance, or the goal clear of the obstacles) or *unchecked* (it cannot tell), with its
evidence. It keeps the planner's rules (the same margins, clearance queries, inverse
kinematics and joint limits) but none of its sampling:

* **inside an obstacle**: coal's distance between the obstacle and a sphere of the stance
  margin about the goal (not the planner's own signed-distance formula): a contact confirms
  it, else it is refuted with the goal's distance from the nearest obstacle.
* **out of reach**: below the floor, or farther in height from the arm's first joint than its
  links stacked straight reach (an upper bound: beyond it no base pose helps), confirms it;
  a goal within the bound is checked as "no stance" is.
* **no stance**: a grid instead of the stance finder's rings: the arm's first joint at every
  node of a square grid (``spacing``, world axes, one node on the goal) within the horizontal
  reach left at the goal's height, the base at ``headings`` headings evenly spaced from 0
  (world frame, not towards the goal), and the robot's own pose. A base pose counts when the
  finder's three conditions hold: the base clear of the obstacles for travel (not asked of the
  robot's own pose), the arm's inverse kinematics
  (:func:`~wmm_control.planning.stance.solve_arm_ik`) from any of the travel posture, the
  dexterous one and ``draws`` postures drawn within the limits (another draw than the
  finder's) reaching the goal, and that posture ``stance_margin`` clear of the obstacles and
  ``body_margin`` of the robot's own links and the floor. The first base pose that counts
  refutes the verdict (with its pose, posture and clearances); none confirms it at that
  grid's resolution (a stance between the nodes, or reached only from other postures, may be
  missed: "no stance" is a sampled verdict, its check another sample on other points, about as
  dense as the finder's two passes).
* **no path**, **timed out**: an occupancy grid of the base (``cell``) over the obstacles, the
  start and the goal's reach, its border clear of them all. A cell is *blocked* when at each
  of ``turns`` headings the robot at its centre, arm in the travel posture, is nearer an
  obstacle than the travel margin less how far a point of the robot moves to any pose of the
  cell between those headings (half the cell's diagonal plus the swept radius times half the
  heading step): no pose in it keeps the margin. A cell is *free* when the upright prism of
  the swept radius at its centre (the robot at any heading) keeps the margin and a check's
  step with half a diagonal to spare. The grid's stances (as above) are sought among the
  cells joined to the start's through unblocked ones (8 neighbours, a superset of where the
  base can go): none there confirms the verdict (the base reaches none of them, whatever
  its path); one on a cell joined to the start's through free cells refutes it (the base
  turns in place and drives straight from cell to cell, keeping the margin all the way: a
  way for a holonomic base, and for a differential one that turns in place, which the
  planner's Reeds–Shepp paths do not); else it is unchecked.
* **start blocked**: unchecked; the evidence is the start's clearance for travel.

Clearances are those of :class:`~wmm_control.planning.clearance.Clearance`, capped at its
influence (0.5 m). The cost is one clearance query per base pose and, where the base is
clear, the inverse kinematics from each posture (a few ms each, 100 steps when it fails): the
grid has about 500 to 1600 base poses for the shipped arms (0.9 to 1.3 m of reach), so a
confirmed "no stance" costs 5 to 40 s on one loaded core, a refuted one usually well under a
second; the path check adds one coal distance per cell and obstacle, and up to ``turns``
clearance queries for the cells near an obstacle (about a second).
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from enum import Enum

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from wmm_control.checks import as_finite_vector
from wmm_control.geometry import rotation_2d, wrap_angle
from wmm_control.planning.outcome import NoWay
from wmm_control.planning.planner import GoalPlanner
from wmm_control.planning.stance import solve_arm_ik

__all__ = ['CheckParams', 'NoWayCheck', 'Verdict', 'confirm_no_way']

#: [m] half the height of the upright prism of the base's swept radius (taller than anything)
PRISM = 50.0


class Verdict(str, Enum):
    """What the check says of the planner's "no way"."""

    CONFIRMED = 'confirmed'
    REFUTED = 'refuted'
    UNCHECKED = 'unchecked'


@dataclass(frozen=True)
class NoWayCheck:
    """The check of one "no way" verdict.

    Attributes:
        verdict: :class:`Verdict`.
        evidence: a sentence: what was checked and what it showed.
        base_pose: refuted by a stance: its base pose (x, y, θ) [m, m, rad]; else None.
        q_arm: the stance's arm posture [rad or m]; else None.
        clearance: [m] the stance's posture from the nearest obstacle; else None.
        body_clearance: [m] between the robot's own links and from the floor there; else None.
        poses: base poses of the grid checked (0: no grid).
        seconds: [s] the check's wall time.
    """

    verdict: Verdict
    evidence: str
    base_pose: np.ndarray | None = None
    q_arm: np.ndarray | None = None
    clearance: float | None = None
    body_clearance: float | None = None
    poses: int = 0
    seconds: float = 0.0

    def as_dict(self) -> dict:
        """The check as JSON-ready values (arrays as lists)."""
        return {
            'verdict': self.verdict.value,
            'evidence': self.evidence,
            'base_pose': None if self.base_pose is None else self.base_pose.tolist(),
            'q_arm': None if self.q_arm is None else self.q_arm.tolist(),
            'clearance_m': self.clearance,
            'body_clearance_m': self.body_clearance,
            'poses': self.poses,
            'seconds': self.seconds,
        }


@dataclass(frozen=True)
class CheckParams:
    """Settings of :func:`confirm_no_way` (module docstring).

    Attributes:
        spacing: [m] between the nodes of the grid of the arm's first joint's positions.
        headings: base headings per node, evenly spaced from 0.
        draws: arm postures drawn within the limits to start the inverse kinematics from,
            besides the travel posture and the dexterous one.
        seed: of those draws.
        cell: [m] of the base's occupancy grid (no path).
        turns: headings a cell is checked at before it counts as blocked (no path).
    """

    spacing: float = 0.2
    headings: int = 12
    draws: int = 1
    seed: int = 7
    cell: float = 0.1
    turns: int = 16


def confirm_no_way(
    planner: GoalPlanner,
    goal_position: ArrayLike,
    goal_rotation: ArrayLike,
    no_way: NoWay | str,
    base_pose: ArrayLike,
    params: CheckParams | None = None,
) -> NoWayCheck:
    """Check the planner's "no way" of kind ``no_way`` for the goal (world position [m],
    rotation (3, 3)), the robot at ``base_pose`` (x, y, θ) when it was found (module docstring).

    Args:
        planner: the planner that found no way (its robot, obstacles, margins and travel posture).
    """
    began = time.perf_counter()
    goal = as_finite_vector(goal_position, 3, 'goal position')
    rotation = np.asarray(goal_rotation, dtype=float)
    base = as_finite_vector(base_pose, 3, 'base pose')
    kind = NoWay(no_way)
    params = params or CheckParams()
    if kind is NoWay.INSIDE_OBSTACLE:
        check = _inside_obstacle(planner, goal)
    elif kind is NoWay.OUT_OF_REACH:
        check = _out_of_reach(planner, goal) or _no_stance(planner, goal, rotation, base, params)
    elif kind is NoWay.NO_STANCE:
        check = _no_stance(planner, goal, rotation, base, params)
    elif kind in (NoWay.NO_PATH, NoWay.TIMED_OUT):
        check = _no_path(planner, goal, rotation, base, params)
    else:
        travel = planner.travel
        check = NoWayCheck(
            Verdict.UNCHECKED,
            f'{kind.value} is not checked: the robot at its pose is {travel.obstacle_clearance(base):.3f} m from '
            f'the obstacles in its travel posture (the path keeps {travel.margin:g} m)',
        )
    return _timed(check, began)


def _timed(check: NoWayCheck, began: float) -> NoWayCheck:
    return NoWayCheck(**{**check.__dict__, 'seconds': time.perf_counter() - began})


def _inside_obstacle(planner: GoalPlanner, goal: np.ndarray) -> NoWayCheck:
    """Coal's distance of a sphere of the stance margin about the goal from each obstacle."""
    margin = planner.stances.params.stance_margin
    sphere = pin.coal.Sphere(margin)
    at = pin.coal.Transform3s(np.eye(3), goal)
    nearest, name = math.inf, ''
    for obstacle in planner.clearance.obstacles:
        placement = pin.coal.Transform3s(obstacle.rotation, obstacle.position)
        result = pin.coal.DistanceResult()
        pin.coal.distance(sphere, at, obstacle.geometry(), placement, pin.coal.DistanceRequest(), result)
        distance = float(result.min_distance)
        if distance < nearest:
            nearest, name = distance, obstacle.name
    if nearest <= 0.0:
        return NoWayCheck(
            Verdict.CONFIRMED,
            f'a sphere of the stance margin ({margin:g} m) about the goal meets the obstacle {name!r} '
            f'({-nearest:.3f} m deep)',
        )
    return NoWayCheck(
        Verdict.REFUTED,
        f'the goal is {nearest + margin:.3f} m from the nearest obstacle ({name!r}), beyond the stance margin '
        f'({margin:g} m)'
        if name
        else 'there is no obstacle',
    )


def _out_of_reach(planner: GoalPlanner, goal: np.ndarray) -> NoWayCheck | None:
    """Confirmed when the goal is below the floor or beyond the arm's height bound; else None."""
    stances = planner.stances
    floor = stances.workspace.floor_z
    if goal[2] < floor:
        return NoWayCheck(Verdict.CONFIRMED, f'the goal is {floor - goal[2]:.3f} m below the floor')
    dz = abs(float(goal[2]) - float(stances.root[2]))
    if dz > stances.reach:
        return NoWayCheck(
            Verdict.CONFIRMED,
            f"the goal is {dz:.3f} m in height from the arm's first joint at any base pose; its links stacked "
            f'straight reach {stances.reach:.3f} m',
        )
    return None


def _grid(planner: GoalPlanner, goal: np.ndarray, params: CheckParams) -> list[np.ndarray]:
    """The base poses of the grid (module docstring): the first joint's nodes within the
    horizontal reach at the goal's height, each at every heading; those halfway out first (the
    arm neither folded nor stretched: a stance, if any, is found sooner)."""
    stances = planner.stances
    dz = float(goal[2]) - float(stances.root[2])
    horizontal = math.sqrt(max(stances.reach**2 - dz**2, 0.0))
    n = int(horizontal // params.spacing)
    steps = np.arange(-n, n + 1) * params.spacing
    offsets = [np.array((x, y)) for x in steps for y in steps if math.hypot(x, y) <= horizontal]
    offsets.sort(key=lambda o: abs(float(np.hypot(*o)) - 0.5 * horizontal))
    headings = [2.0 * math.pi * k / params.headings for k in range(params.headings)]
    poses = []
    for offset in offsets:
        root = goal[:2] + offset
        for heading in headings:
            xy = root - rotation_2d(heading) @ stances.root[:2]
            poses.append(np.array((xy[0], xy[1], wrap_angle(heading))))
    return poses


def _postures(planner: GoalPlanner, params: CheckParams) -> list[np.ndarray]:
    """The arm postures the inverse kinematics starts from (module docstring)."""
    stances = planner.stances
    rng = np.random.default_rng(params.seed)
    lower = np.where(np.isfinite(stances.lower), stances.lower, -math.pi)
    upper = np.where(np.isfinite(stances.upper), stances.upper, math.pi)
    dexterous = np.clip(planner.model.config.arm.dexterous, stances.lower, stances.upper)
    return [planner.travel.q_arm, dexterous] + [rng.uniform(lower, upper) for _ in range(params.draws)]


@dataclass
class _Tally:
    """What the stance grid went through: base poses clear for travel, postures reaching the goal."""

    clear: int = 0
    solved: int = 0


def _stances(
    planner: GoalPlanner,
    goal: np.ndarray,
    rotation: np.ndarray,
    poses: Sequence[np.ndarray],
    tally: _Tally,
    postures: Sequence[np.ndarray],
    own: int | None = None,
) -> Iterator[tuple[int, np.ndarray, np.ndarray, float, float]]:
    """``(index, base pose, q_arm, obstacle clearance, body clearance)`` of each base pose of
    ``poses`` that is a stance by the finder's rules (module docstring; the pose at ``own``
    needs no travel clearance), the first posture that makes it one."""
    stances = planner.stances
    p = stances.params
    for i, pose in enumerate(poses):
        if i != own and not planner.travel.valid(pose):
            continue
        tally.clear += 1
        for start in postures:
            q, pos_err, rot_err = solve_arm_ik(
                planner.model, pose, start, goal, rotation, stances.lower, stances.upper, p
            )
            if pos_err > p.position_tolerance or rot_err > p.orientation_tolerance:
                continue
            tally.solved += 1
            obstacle, body = planner.clearance(q, pose)
            if obstacle >= p.stance_margin and body >= p.body_margin:
                yield i, pose, q, obstacle, body
                break


def _stance_words(pose: np.ndarray, obstacle: float, body: float) -> str:
    return (
        f'base at ({pose[0]:.3f}, {pose[1]:.3f}, {pose[2]:.3f}), the arm {obstacle:.3f} m from the obstacles and '
        f'{body:.3f} m from its own links and the floor'
    )


def _no_stance(
    planner: GoalPlanner, goal: np.ndarray, rotation: np.ndarray, base: np.ndarray, params: CheckParams
) -> NoWayCheck:
    """The grid's first base pose with a clear posture reaching the goal refutes it; none confirms it."""
    p = planner.stances.params
    poses = [base] + _grid(planner, goal, params)
    postures = _postures(planner, params)
    tally = _Tally()
    for i, pose, q, obstacle, body in _stances(planner, goal, rotation, poses, tally, postures, own=0):
        return NoWayCheck(
            Verdict.REFUTED,
            f'a stance: {_stance_words(pose, obstacle, body)} ({i + 1} of {len(poses)} base poses tried)',
            pose,
            q,
            obstacle,
            body,
            i + 1,
        )
    return NoWayCheck(
        Verdict.CONFIRMED,
        f"none of {len(poses)} base poses within the arm's reach ({params.spacing:g} m grid, {params.headings} "
        f"headings, the robot's own pose; {tally.clear} clear for travel) has a posture from {len(postures)} "
        f'starts reaching the goal {p.stance_margin:g} m from the obstacles and {p.body_margin:g} m from its own '
        f'links ({tally.solved} reach it nearer)',
        poses=len(poses),
    )


class _Floor:
    """The base's occupancy grid for the path check (module docstring): cells of ``cell`` [m]
    over every obstacle, the start and the goal's reach, with a border clear of them all."""

    def __init__(self, planner: GoalPlanner, start: np.ndarray, goal: np.ndarray, params: CheckParams) -> None:
        travel, stances = planner.travel, planner.stances
        self.planner = planner
        self.cell = params.cell
        self.turns = params.turns
        self.half = params.cell / math.sqrt(2.0)  # farthest a point of a cell is from its centre
        self.margin = travel.margin
        self.radius = travel.radius
        self.obstacles = planner.travel.clearance.obstacles
        self._prism = pin.coal.Cylinder(self.radius, 2.0 * PRISM)
        self._floor = float(stances.workspace.floor_z)
        reach = stances.reach + float(np.hypot(*stances.root[:2]))
        corners = [start[:2], goal[:2] - reach, goal[:2] + reach]
        for o in self.obstacles:
            extent = {
                'box': 0.5 * float(np.linalg.norm(o.size)),
                'sphere': o.size[0],
                'cylinder': math.hypot(o.size[0], 0.5 * o.size[-1]),
            }[o.shape]  # a sphere about its centre holds it
            corners += [o.position[:2] - extent, o.position[:2] + extent]
        pad = self.radius + self.margin + travel.step + 2.0 * self.cell
        self.lo = np.min(corners, axis=0) - pad
        self.shape = tuple(int(v) for v in np.ceil((np.max(corners, axis=0) + pad - self.lo) / self.cell) + 1)
        self._blocked: dict[tuple[int, int], bool] = {}
        self.prism = np.array(
            [[self.prism_clearance(self.centre((i, j))) for j in range(self.shape[1])] for i in range(self.shape[0])]
        )

    def centre(self, cell: tuple[int, int]) -> np.ndarray:
        return self.lo + self.cell * np.asarray(cell, dtype=float)

    def of(self, xy: ArrayLike) -> tuple[int, int]:
        i, j = np.rint((np.asarray(xy, dtype=float)[:2] - self.lo) / self.cell).astype(int)
        return int(np.clip(i, 0, self.shape[0] - 1)), int(np.clip(j, 0, self.shape[1] - 1))

    def prism_clearance(self, xy: np.ndarray) -> float:
        """[m] from the obstacles of the upright prism of the base's swept radius at ``xy``: the
        robot in its travel posture at any heading there is at least this clear."""
        at = pin.coal.Transform3s(np.eye(3), np.array((xy[0], xy[1], self._floor)))
        nearest = math.inf
        for o in self.obstacles:
            result = pin.coal.DistanceResult()
            placement = pin.coal.Transform3s(o.rotation, o.position)
            pin.coal.distance(self._prism, at, o.geometry(), placement, pin.coal.DistanceRequest(), result)
            nearest = min(nearest, float(result.min_distance))
        return nearest

    def blocked(self, cell: tuple[int, int]) -> bool:
        """Whether no pose of the cell, at any heading, keeps the travel margin: at each of
        ``turns`` headings the robot at the centre is nearer than the margin less how far a
        point moves to any pose of the cell between those headings."""
        if cell not in self._blocked:
            slack = self.half + self.radius * math.pi / self.turns
            xy = self.centre(cell)
            self._blocked[cell] = self.prism[cell] < self.margin - slack and all(
                self.planner.travel.obstacle_clearance((xy[0], xy[1], 2.0 * math.pi * k / self.turns))
                < self.margin - slack
                for k in range(self.turns)
            )
        return self._blocked[cell]

    def region(self, start: tuple[int, int], passable) -> set[tuple[int, int]]:
        """The cells joined to ``start`` through cells ``passable(cell)`` (8 neighbours)."""
        seen, todo = {start}, deque([start])
        while todo:
            i, j = todo.popleft()
            for di in (-1, 0, 1):
                for dj in (-1, 0, 1):
                    n = (i + di, j + dj)
                    if n in seen or not (0 <= n[0] < self.shape[0] and 0 <= n[1] < self.shape[1]):
                        continue
                    if passable(n):
                        seen.add(n)
                        todo.append(n)
        return seen

    def free(self, cell: tuple[int, int]) -> bool:
        """Whether the robot at the centre, at any heading, keeps the margin and a checked pose's
        step, with half a diagonal to spare (any move to a free neighbour keeps them)."""
        return bool(self.prism[cell] >= self.margin + self.planner.travel.step + self.half)

    def joins(self, xy: np.ndarray) -> bool:
        """Whether the base can turn in place at ``xy`` and drive straight to its cell's centre
        keeping the margin (and the cell is free)."""
        cell = self.of(xy)
        gap = 0.5 * float(np.linalg.norm(self.centre(cell) - xy[:2]))
        need = self.margin + self.planner.travel.step + gap
        return self.free(cell) and self.prism_clearance(xy[:2]) >= need


def _no_path(
    planner: GoalPlanner, goal: np.ndarray, rotation: np.ndarray, base: np.ndarray, params: CheckParams
) -> NoWayCheck:
    """Refuted by a stance the base reaches on free cells; confirmed when no stance of the grid
    lies among the cells the base may reach at all; else unchecked."""
    floor = _Floor(planner, base, goal, params)
    start = floor.of(base)
    reachable = floor.region(start, lambda c: not floor.blocked(c))
    poses = [pose for pose in _grid(planner, goal, params) if floor.of(pose) in reachable]
    postures = _postures(planner, params)
    tally = _Tally()
    way = floor.region(start, floor.free) if floor.joins(base) else set()
    found = 0
    for _, pose, q, obstacle, body in _stances(planner, goal, rotation, poses, tally, postures):
        found += 1
        if floor.of(pose) in way and floor.joins(pose):
            return NoWayCheck(
                Verdict.REFUTED,
                f'a way: the base turning in place and driving straight over {params.cell:g} m cells whose every '
                f'heading keeps {floor.margin:g} m from the obstacles reaches a stance ({_stance_words(pose, obstacle, body)})',
                pose,
                q,
                obstacle,
                body,
                tally.clear,
            )
    cells = f'{len(reachable)} of {floor.shape[0] * floor.shape[1]} cells of {params.cell:g} m'
    if not found:
        within = (
            f'none of the {len(poses)} base poses of the grid within them is a stance ({tally.clear} clear for '
            f'travel, {tally.solved} reaching the goal nearer)'
            if poses
            else "none of them has the goal within the arm's reach"
        )
        return NoWayCheck(
            Verdict.CONFIRMED,
            f'the base can reach at most {cells} from its pose (the others nearer than {floor.margin:g} m to an '
            f'obstacle at every heading), and {within}',
            poses=len(poses),
        )
    return NoWayCheck(
        Verdict.UNCHECKED,
        f'{found} stances of the grid lie within the {cells} the base may reach, none on cells clear by its swept '
        f'radius ({floor.radius:.3f} m) joined to its pose',
        poses=len(poses),
    )
