"""Where to stand: base poses from which the arm reaches an end-effector goal, clear of everything.

:class:`StanceFinder` samples base poses around the goal: rings about the goal at fractions of
the horizontal reach left at the goal's height (the arm's length from its first joint, as
:class:`~wmm_control.kinematics.workspace.Workspace` bounds it), at evenly spaced bearings (the
first one on the side of the robot's current pose), each with the base heading towards the goal
and turned from it by a few offsets, and facing away from it (an arm mounted ahead of the base's
centre may reach a goal clear of the obstacles only back over the base). A candidate counts when

1. the base there, arm in the travel posture, is clear of the obstacles by the travel margin
   (:class:`~wmm_control.planning.clearance.Travel`: the base path must be able to end there);
2. the arm's inverse kinematics with the base held there reaches the goal: damped least squares
   on the world pose error ``[p* − p; log(R* Rᵀ)]`` from the travel posture, each step clipped to
   the joint limits less ``limit_margin``, until within ``position_tolerance`` and
   ``orientation_tolerance``. When no candidate gives a stance, the candidates are tried again
   from the dexterous posture and then from postures drawn within the limits (``restarts`` passes
   in all, reproducible): damped least squares finds the posture nearest its start, and a goal
   near the limits may need another branch of the arm (elbow, wrist);
3. that posture keeps ``stance_margin`` from every obstacle and ``body_margin`` between the
   robot's own links and from the floor (the controller's pairs).

Each stance also says whether the arm's way to it keeps those margins (``motion_clear``): the
straight joint-space motion from the travel posture to the stance's, the base at the stance,
which the hand-off gives after the path (:class:`~wmm_control.planning.handoff.Handoff`),
checked every ``motion_step`` on the joint that moves most. A posture can be clear while the
way to it is not: `ur_mecanum`'s arm travels folded, 24 mm from its own body, and the straight
motion to many of its stances passes its forearm within 8–13 mm of its wrist (arm_link_3,
arm_link_5), under the safety stage's d_s = 20 mm. The stage holds the pair at d_s, the motion
stalls there, and the final approach from that posture, on another branch of the arm, failed
(`doorway` goals 3, 5, 7, 35, 47, 72 and 98 of the randomized draw, lost by one or both
velocity-level methods). Such a posture may have no way to it at all under the margins: for
goal 7's, RRT-Connect over the arm's joint space (OMPL, 20 000 iterations, 60 s) found none.

The robot's own base pose is the first candidate (without condition 1: the base is there
already), and comes back first when it is a stance (a goal within reach needs no travel). The
others are tried in order (heading offset first, then bearing, then ring). When none of them
gives a stance, a second pass samples between them: rings halfway between the first ones
(``second_rings``) and the heading every 30° from facing the goal (``second_offsets``), the same
bearings. Among boxes, few candidates are clear for travel and a stance may sit between two
rings or at a heading the first pass leaves out: `clutter` goals 92 and 99 of robot A (11 and 5
clear candidates, none reaching) and 52 of `ur_mecanum` (8 reaching, none with the margins) were
reported "no stance" and refuted by the check (:mod:`~wmm_control.planning.no_way_check`); the
second pass finds stances for all three (the whole search 1–5 s on a loaded 2-core machine). A
goal the first pass finds a stance for costs nothing more. Candidates are tried until ``wanted``
stances with a clear way are found (or ``most_kept`` stances in all); they come back those with
a clear way first, each group best first by ``σ_min + clearance_weight · min(clearance,
clearance_cap)``, σ_min the smallest singular value of the arm's position Jacobian [m/rad] (how
far from a singularity the arm stands) and the clearance from the obstacles [m].

A goal gets no stance, with the reason (:class:`~wmm_control.planning.outcome.NoWay`), when it
is nearer than ``stance_margin`` to an obstacle (or inside one), below the floor or above the
highest the end effector can be, or when no candidate passes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from wmm_control.checks import as_finite_vector
from wmm_control.geometry import pose_error_log, rotation_2d, scale_into_limits, wrap_angle
from wmm_control.kinematics.model import KinematicModel
from wmm_control.kinematics.tasks import ManipulabilityTask
from wmm_control.kinematics.workspace import Workspace
from wmm_control.planning.clearance import Clearance, Travel
from wmm_control.planning.outcome import NoWay
from wmm_control.resolvers.pose_servo import damped_pinv_solve

__all__ = ['Stance', 'StanceParams', 'StanceSearch', 'StanceFinder', 'solve_arm_ik']


@dataclass(frozen=True)
class StanceParams:
    """Settings of :class:`StanceFinder` (module docstring).

    Attributes:
        stance_margin: [m] the clearance of the arm's posture at the stance from every obstacle.
        body_margin: [m] between the robot's own links, and from the floor, at the stance.
        position_tolerance: [m] of the inverse kinematics.
        orientation_tolerance: [rad] of the inverse kinematics.
        ik_iterations: damped least-squares steps per candidate.
        ik_damping: λ of ``Δq = Jᵀ (J Jᵀ + λ² I)⁻¹ e``.
        max_joint_step: [rad or m] the largest change of a joint in one step.
        limit_margin: [rad or m] kept inside the joint position limits.
        rings: the rings' radii as fractions of the horizontal reach at the goal's height.
        bearings: how many bearings around the goal.
        heading_offsets: [rad] the base's heading from facing the goal.
        second_rings: the rings of the second pass, when the first gives no stance.
        second_offsets: [rad] the heading offsets of the second pass.
        wanted: stop when this many stances with a clear way are found.
        most_kept: stop when this many stances are found, clear way or not.
        motion_step: [rad or m] the largest change of a joint between two checked postures of
            the arm's way to the stance.
        restarts: passes over the candidates from other postures when one finds none.
        clearance_weight: [1/m · m/rad] of the clearance in the score.
        clearance_cap: [m] clearance beyond it adds nothing to the score.
    """

    stance_margin: float = 0.03
    body_margin: float = 0.02
    position_tolerance: float = 0.005
    orientation_tolerance: float = 0.01
    ik_iterations: int = 100
    ik_damping: float = 0.05
    max_joint_step: float = 0.3
    limit_margin: float = 0.02
    rings: tuple[float, ...] = (0.45, 0.6, 0.3, 0.75, 0.15)
    bearings: int = 16
    heading_offsets: tuple[float, ...] = (0.0, math.pi / 6, -math.pi / 6, math.pi / 3, -math.pi / 3, math.pi)
    second_rings: tuple[float, ...] = (0.375, 0.525, 0.675, 0.225, 0.825)
    second_offsets: tuple[float, ...] = tuple(k * math.pi / 6 for k in range(12))
    wanted: int = 4
    most_kept: int = 12
    motion_step: float = 0.1
    restarts: int = 2
    clearance_weight: float = 1.0
    clearance_cap: float = 0.3


@dataclass(frozen=True)
class Stance:
    """A base pose and arm posture that reach the goal.

    Attributes:
        base_pose: (x, y, θ) in the world [m, m, rad]. Shape (3,).
        q_arm: the arm's joints there [rad or m]. Shape (n,).
        position_error: [m] of the end effector from the goal.
        orientation_error: [rad].
        clearance: [m] from the nearest obstacle (capped at the clearance's influence).
        body_clearance: [m] between the robot's own links and from the floor (capped likewise).
        sigma_min: [m/rad] smallest singular value of the arm's position Jacobian.
        score: higher is better.
        motion_clear: the straight joint-space motion from the travel posture to ``q_arm``, the
            base at ``base_pose``, keeps the stance's margins (module docstring).
    """

    base_pose: np.ndarray
    q_arm: np.ndarray
    position_error: float
    orientation_error: float
    clearance: float
    body_clearance: float
    sigma_min: float
    score: float
    motion_clear: bool = True


@dataclass(frozen=True)
class StanceSearch:
    """The stances found, best first; or none, with why.

    Attributes:
        stances: best first; empty when there is none.
        no_way: the kind of reason when there is none, else None.
        reason: a sentence for a log ('' when found).
        candidates: base poses sampled.
        solved: candidates whose inverse kinematics reached the goal.
    """

    stances: tuple[Stance, ...]
    no_way: NoWay | None
    reason: str
    candidates: int
    solved: int


def solve_arm_ik(
    model: KinematicModel,
    base_pose: ArrayLike,
    q_start: ArrayLike,
    goal_position: np.ndarray,
    goal_rotation: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    params: StanceParams,
) -> tuple[np.ndarray, float, float]:
    """The arm's inverse kinematics with the base held at ``base_pose`` (module docstring, 2).

    Returns:
        (q_arm, position error [m], orientation error [rad]) of the last step: the first within
        both tolerances, else after ``params.ik_iterations`` steps.
    """
    q = np.clip(np.asarray(q_start, dtype=float), lower, upper)
    step_limit = np.full(q.size, params.max_joint_step)
    for _ in range(params.ik_iterations + 1):
        model.update(base_pose, q)
        error = pose_error_log(goal_position, goal_rotation, *model.ee_placement_world())
        pos_err, rot_err = float(np.linalg.norm(error[:3])), float(np.linalg.norm(error[3:]))
        if pos_err <= params.position_tolerance and rot_err <= params.orientation_tolerance:
            break
        jac = model.arm_jacobian_world('full')
        dq, _ = scale_into_limits(damped_pinv_solve(jac, error, params.ik_damping), step_limit)
        q = np.clip(q + dq, lower, upper)
    return q, pos_err, rot_err


class StanceFinder:
    """Stances for end-effector goals (module docstring).

    Args:
        model: the robot's kinematic model.
        clearance: its clearance among the obstacles.
        travel: the robot driving in its travel posture (the stance's base must be valid there).
        params: :class:`StanceParams`.

    Attributes:
        lower, upper: the arm's position limits less ``limit_margin`` [rad or m] (±inf: none).
        root: the arm's first joint in the base frame [m], the centre of its reach. Shape (3,).
        reach: [m] the most the end effector can be from the first joint (the links' lengths
            stacked, :class:`~wmm_control.kinematics.workspace.Workspace`).
    """

    def __init__(
        self, model: KinematicModel, clearance: Clearance, travel: Travel, params: StanceParams | None = None
    ) -> None:
        self.model = model
        self._manipulability = ManipulabilityTask(model, 'position')
        self.clearance = clearance
        self.travel = travel
        self.params = params or StanceParams()
        self.workspace = Workspace(model)
        arm = model.config.arm
        margin = self.params.limit_margin
        self.lower = np.where(np.isfinite(arm.position_lower), arm.position_lower + margin, -np.inf)
        self.upper = np.where(np.isfinite(arm.position_upper), arm.position_upper - margin, np.inf)
        # the arm's first joint in the base frame: the centre of its reach
        model.update(np.zeros(3), travel.q_arm)
        self.root = model.arm_points_world()[0].copy()
        self.reach = self.workspace.max_height - float(self.root[2])

    def _seeds(self):
        """The arm postures the inverse kinematics starts from, pass by pass: the travel posture,
        the dexterous one, then drawn within the limits (the same draws every time)."""
        yield self.travel.q_arm
        rng = np.random.default_rng(0)
        arm = self.model.config.arm
        lower = np.where(np.isfinite(self.lower), self.lower, -math.pi)
        upper = np.where(np.isfinite(self.upper), self.upper, math.pi)
        for i in range(self.params.restarts):
            yield np.clip(arm.dexterous, self.lower, self.upper) if i == 0 else rng.uniform(lower, upper)

    def refuse(self, goal_position: np.ndarray) -> tuple[NoWay, str] | None:
        """Why no stance can reach a goal at ``goal_position`` whatever the base does, or None."""
        margin = self.params.stance_margin
        for obstacle in self.clearance.obstacles:
            d = obstacle.signed_distance(goal_position)
            if d < margin:
                where = 'inside' if d < 0.0 else f'{d:.3f} m from'
                return NoWay.INSIDE_OBSTACLE, (
                    f'the goal lies {where} the obstacle {obstacle.name!r} ({obstacle.shape}); '
                    f'the stance keeps {margin:g} m from obstacles'
                )
        why = self.workspace.impossible(goal_position)
        if why:
            return NoWay.OUT_OF_REACH, f'the goal is out of reach: {why}'
        if abs(float(goal_position[2]) - float(self.root[2])) > self.reach:
            return NoWay.OUT_OF_REACH, (
                f'the goal is out of reach: {abs(goal_position[2] - self.root[2]):.3f} m from the height of '
                f"the arm's first joint, which reaches {self.reach:.3f} m at most"
            )
        return None

    def candidates(self, goal_position: np.ndarray, base_pose: np.ndarray, second: bool = False) -> list[np.ndarray]:
        """The base poses to try for a goal at ``goal_position``, in order: ``base_pose`` (x, y,
        θ), where the robot is, then the samples, the first bearing on its side; with ``second``,
        the second pass's samples alone (module docstring)."""
        p = self.params
        rings, offsets = (p.second_rings, p.second_offsets) if second else (p.rings, p.heading_offsets)
        dz = float(goal_position[2]) - float(self.root[2])
        horizontal = math.sqrt(max(self.reach**2 - dz**2, 0.0))
        goal_xy = np.asarray(goal_position[:2], dtype=float)
        away = base_pose[:2] - goal_xy
        first = math.atan2(away[1], away[0]) if np.any(away) else 0.0
        out = [] if second else [base_pose]
        for offset in offsets:
            for i in range(p.bearings):
                bearing = first + 2.0 * math.pi * i / p.bearings  # from the goal to the arm's root
                for fraction in rings:
                    r = fraction * horizontal
                    root = goal_xy + r * np.array((math.cos(bearing), math.sin(bearing)))
                    heading = wrap_angle(bearing + math.pi + offset)
                    base_xy = root - rotation_2d(heading) @ self.root[:2]
                    out.append(np.array((base_xy[0], base_xy[1], heading)))
        return out

    def way_clear(self, q_arm: np.ndarray, base_pose: np.ndarray) -> bool:
        """Whether the straight joint-space motion from the travel posture to ``q_arm``, the base
        at ``base_pose``, keeps ``stance_margin`` from the obstacles and ``body_margin`` from the
        body at every checked posture, ``motion_step`` apart on the joint that moves most (from
        the travel posture on; ``q_arm`` itself is the stance's, which :meth:`find` has checked)."""
        p = self.params
        start = np.asarray(self.travel.q_arm, dtype=float)
        steps = int(math.ceil(float(np.max(np.abs(q_arm - start), initial=0.0)) / p.motion_step))
        for s in np.linspace(0.0, 1.0, steps + 1)[:-1]:
            obstacle, body = self.clearance(start + s * (q_arm - start), base_pose)
            if obstacle < p.stance_margin or body < p.body_margin:
                return False
        return True

    def find(self, goal_position: ArrayLike, goal_rotation: ArrayLike, base_pose: ArrayLike) -> StanceSearch:
        """Stances for the goal (world position [m], rotation (3, 3)), best first (module docstring).

        Args:
            goal_position: (x, y, z) [m].
            goal_rotation: the end effector's orientation in the world. Shape (3, 3).
            base_pose: (x, y, θ) [m, m, rad] where the robot is now.
        """
        goal_position = as_finite_vector(goal_position, 3, 'goal position')
        goal_rotation = np.asarray(goal_rotation, dtype=float)
        refused = self.refuse(goal_position)
        if refused is not None:
            return StanceSearch((), refused[0], refused[1], 0, 0)
        p = self.params
        base_pose = as_finite_vector(base_pose, 3, 'base pose')
        found: list[Stance] = []
        tried = blocked = solved = 0
        for second in (False, True):
            candidates = self.candidates(goal_position, base_pose, second)
            clear: dict[int, bool] = {} if second else {0: True}  # the robot's own pose needs no travel there
            solved += self._search(candidates, clear, goal_position, goal_rotation, found)
            tried, blocked = tried + len(clear), blocked + sum(not ok for ok in clear.values())
            if found:
                break
        if found:
            here = found[0] if found[0].base_pose is base_pose else None  # the robot's own pose first
            found.sort(key=lambda s: (s is not here, not s.motion_clear, -s.score))
            return StanceSearch(tuple(found), None, '', tried, solved)
        if blocked == tried:
            reason = 'no base pose around the goal is clear of the obstacles'
        elif solved == 0:
            reason = f'the arm reaches the goal from none of the {tried - blocked} clear base poses around it'
        else:
            reason = (
                f'the arm reaches the goal from {solved} base poses, none with {p.stance_margin:g} m from the '
                f'obstacles and {p.body_margin:g} m between its own links'
            )
        return StanceSearch((), NoWay.NO_STANCE, f'no stance: {reason}', tried, solved)

    def _search(self, candidates, clear: dict[int, bool], goal_position, goal_rotation, found: list[Stance]) -> int:
        """Try ``candidates`` from each seed posture in turn, adding the stances to ``found``,
        until a seed gives some (``wanted`` with a clear way, or ``most_kept`` in all); ``clear``
        keeps whether each candidate asked is valid for travel (asked once). Returns how many
        times the inverse kinematics reached the goal."""
        p = self.params
        solved = clear_ways = 0
        for seed in self._seeds():
            for i, base in enumerate(candidates):
                if i not in clear:
                    clear[i] = self.travel.valid(base)
                if not clear[i]:
                    continue
                q, pos_err, rot_err = solve_arm_ik(
                    self.model, base, seed, goal_position, goal_rotation, self.lower, self.upper, p
                )
                if pos_err > p.position_tolerance or rot_err > p.orientation_tolerance:
                    continue
                solved += 1
                obstacle, body = self.clearance(q, base)
                if obstacle < p.stance_margin or body < p.body_margin:
                    continue
                self.model.update(base, q)
                sigma = self._manipulability.sigma_min()
                score = sigma + p.clearance_weight * min(obstacle, p.clearance_cap)
                way = self.way_clear(q, base)
                found.append(Stance(base, q, pos_err, rot_err, obstacle, body, sigma, score, way))
                clear_ways += way
                if clear_ways >= p.wanted or len(found) >= p.most_kept:
                    return solved
            if found:
                return solved
        return solved
