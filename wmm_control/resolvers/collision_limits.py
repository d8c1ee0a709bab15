"""The safety stage's limits, each a :class:`~wmm_control.resolvers.constraints.Constraint` on
the cycle's command: the velocity dampers that keep the arm off the robot's own body, off
itself and off the floor, and the whole robot off obstacles (:class:`VelocityDampers`), and the
rows of a base that lags its reference or turns (:class:`BaseRows`), and the arm's stopping turn
(:meth:`VelocityDampers.stopping`). The stage
(:mod:`~wmm_control.resolvers.safety`) stacks them and sends the command nearest the method's
under them.

**The command and the pairs.** The command ``q̇`` holds the base's axes (when the method
commands the base with it; :attr:`Pairs.axes` of (vx, vy, ω), in the base's frame or as the
world frame's rates), then the arm's joints. Each checked pair closer than the look-ahead
(:class:`~wmm_control.kinematics.collision.CollisionModel`) has its distance's rate
``ḋ = j · q̇``: one linear row on the command (:class:`Pairs`). A base twist that is not part
of the command (the base controller's, when only the arm is left to choose) moves each row's
bound by its share.

**Velocity dampers** (:class:`VelocityDampers`, one row per pair in the parts ``self``,
``floor`` and ``obstacle``). For each checked pair closer than the influence distance ``d_i``
the distance may shrink no faster than (Faverjon and Tournassoud's velocity damper)

    ḋ ≥ −ξ (d − d_s) / (d_i − d_s),

so the arm may approach at ``ξ`` at the influence distance, ever more slowly nearer, and not
at all at the safety distance ``d_s`` (below it, the pair must move apart). An arm that
arrives at ``d_i`` much faster than ``ξ`` cannot slow down to it at once within its
acceleration limits, so a pair closer than the look-ahead distance ``d_b`` (≥ ``d_i``) also
keeps its approach within what braking at ``a_b`` can stop before ``d_s``:

    ḋ ≥ −√(2 a_b (d − d_s)),

the stricter of the two where both hold. ``a_b`` is taken no larger than the deceleration the
robot's acceleration limits can give that distance (``Σ_i |j_i| q̈_max,i`` over the arm's
joints, plus ``|j_xy|`` times the slower of the base's linear axes: the pair's normal turns
under a base that brakes, so both axes are not counted on at once; for a pair of the base's own
body, where the base tracks its reference, also ``|j_ω|`` times its turn's limit, the row
without the turn's share below keeping its linear approach to the linear axes' braking): a
Mecanum base that brakes at 0.025 m/s² is not counted on to stop at 1 m/s². The base's share
counts whether or not its twist is part of the command: a twist given for the period (the base controller's answer, with
only the arm left to choose) brakes from the next period on all the same, so a pair is allowed
the same approach either way. With obstacles, whose distance the base's
twist changes too, the look-ahead grows to the base's stopping distance from full speed
(``d_s + v τ + v² / (2 min(a, a_b))``, ``v`` the norm of the linear axes' speed limits, since
the base may drive on a diagonal, and ``a`` the deceleration its rows count on: the slower
axis's limit, less the turn's share below) so that it brakes in time.

**The arm's stopping turn** (:meth:`VelocityDampers.stopping`, ``arm stopping``, one row per
pair an arm joint moves). The rows above bound the distance's rate at this configuration. A
joint that turns fast curves its points' paths: a point at ``r`` from the joint's axis, turned
by ``θ``, leaves its tangent by ``r (1 − cos θ) ≤ r θ² / 2``, towards the other shape as easily
as away, and no row on ``ḋ`` sees it until the pair's normal has turned. Braking at its
acceleration limit from ``q̇_i``, joint ``i`` still turns ``θ_i = q̇_i² / (2 q̈_max,i)``, so each
pair keeps

    Σ_i r_i θ_i² / 2 ≤ max(d, d_s) − d_s / 2,

``r_i`` the speed joint ``i`` gives the pair's two nearest points apart, in any direction
(:attr:`~wmm_control.kinematics.collision.NearPairs.lever`). The row is quartic and convex in
``q̇``; over the period's box each ``q̇_i⁴`` is replaced by its chord, which lies above it there,
so the linear row implies the quartic one within the box. At a few rad/s² a joint at 1 rad/s
turns some 0.1 rad to stop, a few mm at ``r`` = 1 m: the row binds only on joints that turn fast
near something (robot B's wrist spun at 3.14 rad/s 10 cm from a wall turns about 1 rad per
joint to stop, and swung its gripper 2.8 cm into the wall before this row).

**A base that lags its reference** (:class:`BaseRows`). The stage shapes the base's
*reference*; a base whose twist follows its reference with a lag τ (a steerable base's ICR and
twist controllers, ICṘ = λ (ICR* − ICR), ξ̈ = K_p (ξ̇* − ξ̇): lags in series, τ = 1/K_p + 1/λ,
0.75 s on robot A; the running base controller's
:attr:`~wmm_control.base.BaseController.lag`) drives on at about the reference of τ ago. One
model of it, five kinds of row and one hold:

- *braking after the lag* (in the dampers): a row the base moves (a pair with an obstacle)
  counts on stopping within ``v τ + v² / (2 a_b)``,
  ``ḋ ≥ −a_b (√(τ² + 2 (d − d_s) / a_b) − τ)``, its damper gain no steeper than ``1/τ``; and
  the base's own body (chassis, wheels) keeps ``collision_lag_margin`` more than ``d_s`` from
  obstacles: while its wheels steer from one ICR to another its twist sweeps through directions
  that neither its reference nor its measured twist has (robot A spinning beside the pillar
  approached it faster and faster for 0.3 s while its reference asked it away), which no lag
  on each axis describes;
- *held on its path* (:meth:`BaseRows.hold_on_path`): where the base's measured twist ``v₀``
  already approaches a pair faster than allowed (it lagged, or a steerable base swept its
  wheels round towards the obstacle while changing its ICR), the base is sent ``s v₀``, a
  twist on its own path, which a steerable base follows by slowing its wheels without steering
  them, with ``s`` low enough (down to −1, or lower where a pair must separate faster than the
  base approaches it) to brake the approach within the room left, within the method's box;
- ``base along path`` (:meth:`BaseRows.along_path`): the part of the reference along ``v₀``
  meets the same row as the reference: a steerable base first drives on along its path at that
  part while its wheels turn to the new one;
- ``base between`` (:meth:`BaseRows.between`): the row at every corner of the box between the
  measured twist and the reference, axis by axis (the base gets to its reference on each axis
  at its own pace: a steerable base drives on along its wheels' heading, and turns, before it
  has steered to a sideways reference);
- ``base after turn`` (:meth:`BaseRows.after_turn`): the row against the pair's normal as the
  base will see it after the turn it cannot stop at once (turned by ω τ, and for a reference in
  the base's frame, which turns with it, by the turn's braking ω |ω| / (2 α) too).

**A base that tracks its reference** (τ = 0: a wheeled base within its acceleration limits)
has none of the above, and

- ``base without turn`` (:meth:`BaseRows.without_turn`): for a pair of its own body (chassis,
  wheels) and an obstacle, the row also holds without the turn's share, braked by the linear
  axes alone: a turn that swings one corner away for the moment cannot hide a linear approach
  faster than the base can stop.

**Every base that turns while it drives** (its reference in its own frame):

- ``base turn rate`` (:meth:`BaseRows.turn_rate`): a row on the turn rate keeps the turn from
  turning the base's velocity towards an obstacle (at v ω, v its measured speed) by more than
  :data:`TURN_SHARE` of the linear deceleration; the braking rows of a tracking base count on
  the rest.

At acceleration level (Xing's methods) the stage acts on the rates the method has integrated
for this period, within its box of ``q̇_prev ± q̈_max T``: a row ``j · (q̇_prev + q̈ T) ≥ b``
is the matching bound on the acceleration, ``j · q̈ ≥ (b − ḋ_prev) / T`` (the dampers
discretised over the period, J̇'s share neglected).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike

from wmm_control.geometry import rotation_z
from wmm_control.kinematics.collision import NearPairs
from wmm_control.resolvers.constraints import TOLERANCE, Box, Constraint

__all__ = ['Pairs', 'VelocityDampers', 'BaseRows', 'LIMITS', 'TURN_SHARE', 'PATH_SPEED']

#: [m/s] a lagging base's measured twist below this tells no path (at rest).
PATH_SPEED = 1e-4
#: The share of a wheeled base's linear deceleration near obstacles that its turn may take
#: (turning under a moving base turns its path, towards an obstacle too, and the linear axes
#: must brake that); the dampers count on the rest.
TURN_SHARE = 0.25
#: The corners of the box between a lagging base's measured twist and its reference other than
#: the reference itself: the axes (vx, vy, ω) on which each takes the reference.
_PARTS = np.array(((1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (1, 0, 1), (0, 1, 1)), dtype=float)
_LINEAR = np.array([1.0, 1.0, 0.0])
#: The dampers' constraints, in the order of the pairs' kinds.
_KINDS = ('self', 'floor', 'obstacle')
#: The arm's stopping reach (:meth:`VelocityDampers.stopping`).
_STOPPING = 'arm stopping'
#: The base's constraints (:class:`BaseRows`).
_ALONG, _BETWEEN, _AFTER, _WITHOUT, _TURN = (
    'base along path',
    'base between',
    'base after turn',
    'base without turn',
    'base turn rate',
)
#: The name of every limit's constraint (:attr:`~wmm_control.resolvers.constraints.Constraint.name`):
#: what the safety stage's diagnostics count.
LIMITS = (*_KINDS, _STOPPING, _ALONG, _BETWEEN, _AFTER, _WITHOUT, _TURN)


@dataclass(frozen=True)
class Pairs:
    """The cycle's checked pairs over the command: pair ``k``'s rate is ``rows[k] · q̇`` (plus the
    base's share when the base is not part of the command), and its damper asks
    ``rows[k] · q̇ ≥ bound[k]``.

    Attributes:
        rows: over the command (the base's ``axes``, then the arm's joints). Shape (m, n).
        bound: the dampers' bounds [m/s]. Shape (m,).
        base: ``j_b`` over the base's twist (vx, vy, ω) in its own frame. Shape (m, 3).
        distance: the distances the dampers brake to [m] (a lagging base's body margin taken
            off its body's pairs). Shape (m,).
        moved: the pairs the base's twist moves (with an obstacle). Shape (m,), boolean.
        body: the pairs of the base's own body (no arm joint moves them: chassis, wheels) and an
            obstacle. Shape (m,), boolean.
        axes: indices into (vx, vy, ω) of the command's base entries.
        to_base: the command's base entries as (vx, vy, ω): the identity, or R(θ)ᵀ for the
            world frame's rates. Shape (3, 3).
        kinds: ``(kind, pairs)`` in order: the robot against itself (``self``), the floor
            (``floor``), obstacles (``obstacle``); the pairs come in that order.
        turn_braking: how much of each bound's approach is the braking of the base's turn [m/s]
            (:meth:`VelocityDampers._allowed`; zero where it is not counted): ``bound +
            turn_braking`` is the bound the base's linear approach alone meets
            (:meth:`BaseRows.without_turn`). Shape (m,).
        lever: each arm joint's reach on the pair, ``|v_b − v_a|`` per unit rate
            (:attr:`~wmm_control.kinematics.collision.NearPairs.lever`). Shape (m, n_arm).
    """

    rows: np.ndarray
    bound: np.ndarray
    base: np.ndarray
    distance: np.ndarray
    moved: np.ndarray
    body: np.ndarray
    axes: tuple[int, ...]
    to_base: np.ndarray
    kinds: tuple[tuple[str, int], ...]
    turn_braking: np.ndarray
    lever: np.ndarray

    def with_twist(self, base_twist) -> Pairs:
        """The same rows with the bounds moved by the share of ``base_twist`` (vx, vy, ω), the
        base's twist when it is not part of the command; ``self`` for None."""
        if base_twist is None:
            return self
        return replace(self, bound=self.bound - self.base @ np.asarray(base_twist, dtype=float))

    def on_base(
        self, base: np.ndarray, shift: ArrayLike = 0.0, which: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """The rows of the pairs ``which`` (default: the ones the base moves) again, with the base
        part ``base`` (over (vx, vy, ω) in the command's terms, one row per such pair) and the
        bound plus ``shift``: ``(rows, bound)``, rows ``rows · q̇ ≥ bound``. ``base`` of shape
        (c, k, 3) and ``shift`` of shape (c, k) give ``c`` such sets of rows, one after the other."""
        which = self.moved if which is None else which
        nb = len(self.axes)
        part = base[..., self.axes].reshape(-1, nb)
        arm = self.rows[which, nb:]
        if base.ndim == 3:  # the arm's part again for each set
            arm = np.tile(arm, (base.shape[0], 1))
        return np.concatenate((part, arm), axis=1), (self.bound[which] + shift).reshape(-1)


def linear_axes(axes, base_acceleration) -> tuple[list[int], float]:
    """The command's entries on the base's linear axes, and the slower axis's acceleration
    limit [m/s²] (0 without them)."""
    linear = [k for k, axis in enumerate(axes) if axis < 2]
    return linear, (float(np.min(base_acceleration[[axes[k] for k in linear]])) if linear else 0.0)


class VelocityDampers:
    """The velocity dampers of the module docstring: one row per pair.

    Args:
        params: :class:`~wmm_control.resolvers.safety.SafetyParams`.
        arm_acceleration: the arm joints' acceleration limits, or None (every row brakes at
            ``collision_braking``).
        base_acceleration: the base's limits on (vx, vy, ω). Shape (3,).
        lag: τ [s] of the base.
        body_margin: [m] the room the base's body keeps from obstacles beyond d_s.
    """

    def __init__(self, params, arm_acceleration, base_acceleration, lag: float, body_margin: float):
        self.params = params
        self.arm_acceleration = arm_acceleration
        self.base_acceleration = base_acceleration
        #: the base's axes, indices into (vx, vy, ω): those it can accelerate on
        self.base_axes = tuple(int(k) for k in np.flatnonzero(np.asarray(base_acceleration) > 0.0))
        self.lag = lag
        self.body_margin = body_margin
        self._last: tuple = (None, None)  # (near pairs, their bounds) of the last pairs()

    def pairs(self, near: NearPairs, axes: tuple[int, ...], to_base: np.ndarray) -> Pairs:
        """The rows and bounds of the pairs ``near`` over a command whose base entries are
        ``axes`` (through ``to_base``), the robot's own pairs first, then those with the floor,
        then those with obstacles (a base's twist outside the command: :meth:`Pairs.with_twist`).
        The bounds do not depend on the command's entries: asked again about the same ``near``
        (a method's second pass in one period, eq (14)'s compensation over the arm alone), they
        are the first call's."""
        if self._last[0] is not near:
            self._last = (near, self._bounds(near))
        base_full, rate, distance, moved, body, bound, kinds, turn, lever = self._last[1]
        rows = np.concatenate(((base_full @ to_base)[:, axes], rate), axis=1)
        return Pairs(rows, bound, base_full, distance, moved, body, tuple(axes), to_base, kinds, turn, lever)

    def _bounds(self, near: NearPairs) -> tuple:
        """What :meth:`pairs` gives that the command's entries leave as it is, in its order:
        ``(base, rate, distance, moved, body, bound, kinds, turn_braking, lever)``."""
        base_full, rate, distance, lever = near.base_jacobian, near.rate_jacobian, near.distance, near.lever
        moved = np.asarray(base_full.any(axis=1), dtype=bool)
        kind = 2 * moved + near.floor
        if (kind[1:] < kind[:-1]).any():
            order = np.argsort(kind, kind='stable')
            base_full, rate, distance, lever = base_full[order], rate[order], distance[order], lever[order]
            moved, kind = moved[order], kind[order]
        body = moved & ~rate.any(axis=1)
        if self.body_margin > 0.0:  # a lagging base's body keeps its margin: its pairs are as much nearer
            distance = distance - self.body_margin * body
        turning = self.lag == 0.0 and 2 in self.base_axes  # a tracking base's turn brakes its body's pairs
        allowed = self._allowed(distance, rate, base_full, moved, body if turning else None)
        turn = allowed - self._allowed(distance, rate, base_full, moved) if turning else np.zeros(len(distance))
        counts = np.bincount(kind, minlength=3).tolist()
        kinds = tuple((name, count) for name, count in zip(_KINDS, counts) if count)
        return base_full, rate, distance, moved, body, -allowed, kinds, turn, lever

    def constraints(self, pairs: Pairs) -> Constraint:
        """The dampers, one row per pair: ``self`` (the robot against itself), ``floor`` and
        ``obstacle``."""
        return Constraint(-pairs.rows, -pairs.bound, 'dampers', pairs.kinds)

    def stopping(self, pairs: Pairs, box: Box) -> Constraint:
        """``arm stopping``, one row per pair that an arm joint moves: what the turn of the
        pair's points while the arm's joints brake adds to their approach (the module
        docstring), within the room the pair has. The row is the chord of that quartic over
        the period's box, a linear row that implies it there. No rows without the arm's
        acceleration limits."""
        nb = len(pairs.axes)
        if self.arm_acceleration is None:
            return Constraint.empty(pairs.rows.shape[1], _STOPPING)
        lower, upper = box.lower[nb:], box.upper[nb:]
        # r θ²/2 with θ = q̇² / (2 a): r q̇⁴ / (8 a²), and q̇⁴ ≤ l⁴ + s (q̇ − l) on [l, u], s the
        # chord's slope (u + l)(u² + l²) (0 where the box holds the joint at l)
        weight = pairs.lever / (8.0 * self.arm_acceleration**2)
        slope = np.where(upper > lower, (upper + lower) * (upper**2 + lower**2), 0.0)
        G = np.zeros((len(pairs.lever), nb + lower.size))
        G[:, nb:] = weight * slope
        safety = self.params.collision_safety
        room = np.maximum(pairs.distance, safety) - 0.5 * safety
        h = room - weight @ (lower**4 - slope * lower)
        # a row that holds at every corner of the box holds in all of it (the chord is linear and
        # meets the quartic at the box's ends): it can never bind, and the QP is spared it
        reaches = weight @ np.maximum(lower**4, upper**4) > room
        keep = reaches & pairs.lever.any(axis=1) & np.isfinite(G).all(axis=1) & np.isfinite(h)
        return Constraint(G[keep], h[keep], _STOPPING)

    def _allowed(self, distances, arm_rows, base_rows, moved, turning=None) -> np.ndarray:
        """Each pair's fastest allowed approach [m/s], braking no harder than the acceleration
        limits can slow that distance: the arm's (``arm_rows``, over its joints) and the base's
        linear axes (``base_rows``, over (vx, vy, ω)), whether or not the base is part of the
        command: a base twist given for this period (the base controller's answer, eq 14's
        call) brakes from the next period on as a base in the command does, so both calls allow
        a pair the same approach. (Counting on the arm alone there, a pair the arm barely moves,
        its first links, was allowed no approach at all while the base drove at an obstacle
        within the look-ahead, and the stage wound the arm to cancel the base's approach at
        them.) For a pair of the base's own body and an obstacle (``turning``, boolean per pair;
        None: none), the turn brakes too, ``|j_ω|`` times its acceleration limit, where the base
        tracks its reference (τ = 0):
        turning swings the near point aside for a moment, but does not stop a base that drives
        at an obstacle, and there the row without the turn's share
        (:meth:`BaseRows.without_turn`) keeps the linear approach within what the linear axes
        brake (the arm's pairs, which have no such row, count the arm and the linear axes). Left
        out, a pair that only the turn moves (a differential base's wheel beside an obstacle, its
        normal across the heading: ``j_x = 0``) had nothing to brake it and was allowed no
        approach anywhere within the look-ahead: the base could not turn that way at all
        (`panda_diff` stopped 0.28 rad off its stance's heading beside the table of
        `table_pillar`, and task sharing's final approach from there stalled)."""
        lags = np.where(moved, self.lag, 0.0)
        if self.arm_acceleration is None:
            return np.asarray(self.allowed_approach(distances, lag=lags))
        reach = np.abs(arm_rows) @ self.arm_acceleration
        linear, slowest = self.linear_braking(self.base_axes)
        if linear:
            # the base's linear axes brake the distance at no more than |j_xy| times that,
            # whichever way the pair's normal turns while it brakes (Σ |j_i| a_i would count on
            # braking both axes at once along a normal that the base's turn, or its approach to
            # another face, changes under it)
            columns = [self.base_axes[k] for k in linear]
            reach = reach + np.linalg.norm(base_rows[:, columns], axis=1) * slowest
        if turning is not None:
            reach = reach + np.where(turning, np.abs(base_rows[:, 2]) * float(self.base_acceleration[2]), 0.0)
        return np.asarray(self.allowed_approach(distances, reach, lags))

    def linear_braking(self, axes) -> tuple[list[int], float]:
        """The command's entries on the base's linear axes (its entries ``axes`` of (vx, vy, ω)),
        and the deceleration [m/s²] the rows count on along them: the slower axis's limit, less
        the turn's share where the base tracks its reference and turns (the rest is the turn's:
        :meth:`BaseRows.turn_rate`); 0 without linear axes."""
        linear, slowest = linear_axes(axes, self.base_acceleration)
        if linear and 2 in axes and self.lag == 0.0:
            slowest *= 1.0 - TURN_SHARE
        return linear, slowest

    def stopping_distance(self, speed: float, deceleration: float) -> float:
        """The nearest a pair that the base moves may be [m] and still approach at ``speed``
        [m/s] (:meth:`allowed_approach`'s braking, inverted): d_s, then the way the base goes
        on at that speed for its lag, then the way it takes to stop, braking at ``deceleration``
        [m/s²] and no harder than ``collision_braking``."""
        p = self.params
        if speed == 0.0:
            return p.collision_safety
        a = min(p.collision_braking, deceleration)
        return p.collision_safety + speed * self.lag + (speed * speed / (2.0 * a) if a > 0.0 else math.inf)

    def allowed_approach(
        self, distance: ArrayLike, deceleration: ArrayLike = math.inf, lag: ArrayLike = 0.0
    ) -> float | np.ndarray:
        """The fastest a pair ``distance`` [m] apart may approach [m/s] (negative: it must
        separate), its distance braking at no more than ``deceleration`` [m/s²] (and
        ``collision_braking``) after a lag of ``lag`` [s]. Each argument a number or an array
        (one entry per pair); the answer is a float for numbers, else an array."""
        p = self.params
        d_i, d_s = p.collision_influence, p.collision_safety
        distance = np.asarray(distance, dtype=float)
        lag = np.asarray(lag, dtype=float)
        a = np.minimum(p.collision_braking, deceleration)
        room = np.maximum(distance - d_s, 0.0)
        with np.errstate(divide='ignore', invalid='ignore', over='ignore'):  # a tiny a: inf, then min
            braking = np.where(a > 0.0, a * (np.sqrt(lag * lag + 2.0 * room / a) - lag), 0.0)
            slope = p.collision_gain / (d_i - d_s)
            gain = np.where(lag > 0.0, np.minimum(slope, 1.0 / lag), slope)
        damper = np.where(distance < d_i, gain * (distance - d_s), math.inf)
        out = np.minimum(damper, braking)
        return float(out) if out.ndim == 0 else out


class BaseRows:
    """The rows of a base that lags its reference or turns (the module docstring).

    Args:
        safety_distance: d_s [m].
        base_acceleration: the base's limits on (vx, vy, ω) [m/s², rad/s²]. Shape (3,).
        lag: τ [s] of the base.
    """

    def __init__(self, safety_distance: float, base_acceleration: np.ndarray, lag: float):
        self.safety_distance = safety_distance
        self.base_acceleration = base_acceleration
        self.lag = lag

    def constraints(
        self, pairs: Pairs, command, box: Box, base_velocity=None, base_twist=None, world_rates=False
    ) -> tuple[np.ndarray, Box, bool, list[Constraint]]:
        """The cycle's base rows, and the command and box with the base held on its path where
        it must be (:meth:`hold_on_path`): ``(command, box, held, constraints)``.

        Args:
            pairs: the cycle's :class:`Pairs`.
            command, box: the method's command and the period's box.
            base_velocity: the base's measured twist (vx, vy, ω), or None.
            base_twist: the base's twist when it is not part of the command (then no base rows).
            world_rates: the command's base entries are the world frame's (ẋ, ẏ, θ̇).
        """
        out: list[Constraint] = []
        held = False
        if base_twist is not None:
            return command, box, held, out
        axes = pairs.axes
        if axes and base_velocity is not None and self.lag > 0.0:
            v0 = np.asarray(base_velocity, dtype=float)
            own = pairs.base @ v0  # the base's approach rates
            command, box, held = self.hold_on_path(pairs, command, box, v0, own)
            out += [
                self.along_path(pairs, v0, own),
                self.between(pairs, v0),
                self.after_turn(pairs, v0, command, world_rates),
            ]
        if self.lag == 0.0:
            # a base that tracks its reference: its linear approach must brake on its own (a
            # lagging base's is held along its measured path above)
            out.append(self.without_turn(pairs))
        if pairs.moved.any() and not world_rates:
            out.append(self.turn_rate(pairs, base_velocity))
        return command, box, held, out

    def hold_on_path(self, pairs: Pairs, command, box: Box, v0, own) -> tuple[np.ndarray, Box, bool]:
        """A lagging base that already approaches a pair faster than allowed (its measured twist
        ``v0``, approach rates ``own`` = j_b v₀, with the arm's share of ``command``) is sent
        ``s v₀`` instead of its reference: the largest ``s`` in [−1, 1] that the pairs allow. That
        twist lies on the base's own path (a steerable base keeps its ICR and only slows its
        wheels: no re-steering, whose sweep would carry it on towards the obstacle), and the base
        entries are held there in the box. Returns ``(command, box, held)``."""
        axes, rows, bound = pairs.axes, pairs.rows, pairs.bound
        nb = len(axes)
        arm = rows[:, nb:] @ command[nb:]
        approaching = pairs.moved & (own < -TOLERANCE)
        if not (approaching & (own + arm < bound - TOLERANCE)).any():
            return command, box, False
        # the approach at the pair's bound once the base has settled at s v₀, and braking at
        # K_p (1 − s) |ḋ_b| from now on strong enough to stop it within the room left
        room = np.maximum(pairs.distance[approaching] - self.safety_distance, 1e-6)
        settle = min(1.0, float(np.min((bound - arm)[approaching] / own[approaching])))
        scale = min(settle, float(np.min(1.0 + own[approaching] * self.lag / (2.0 * room))))
        # back along the path at up to the speed it came, or as fast as a pair must separate (a
        # base that crept inside the safety distance at a crawl must leave faster than it came)
        scale = max(scale, min(-1.0, settle))
        # the twist in the command's terms, v₀ᵀ R(θ)ᵀ = (R(θ) v₀)ᵀ (to_base is a rotation), within the
        # method's box: the reference changes no faster than its own limits allow
        target = np.clip((v0 @ pairs.to_base)[list(axes)] * scale, box.lower[:nb], box.upper[:nb])
        command = command.copy()
        command[:nb] = target
        return command, box.hold(slice(0, nb), target), True

    def along_path(self, pairs: Pairs, v0, own) -> Constraint:
        """For each pair the base moves, the same row on the part of the reference along the
        base's measured twist ``v0`` (``own`` = j_b v₀): a steerable base first moves along its
        current path, at that part, while its wheels turn towards the reference's (a sideways
        reference drives it on along its wheels' heading for a while, into what lies ahead)."""
        n = pairs.rows.shape[1]
        norm = float(v0 @ v0)
        if norm < PATH_SPEED**2 or not pairs.moved.any():
            return Constraint.empty(n, _ALONG)
        along = (own[pairs.moved, None] * v0 / norm) @ pairs.to_base  # j_b v₀ v₀ᵀ / |v₀|²
        return Constraint.from_lower(*pairs.on_base(along), _ALONG)

    def between(self, pairs: Pairs, v0) -> Constraint:
        """For each pair the base moves, the row at every corner of the box between the base's
        measured twist ``v0`` and its reference, axis by axis (vx, vy, ω of its own frame): a
        lagging base gets to its reference on each axis at its own pace (a steerable base drives
        on along its wheels' heading, and turns, before it has steered to a sideways reference),
        so a reference whose approach is a part towards the obstacle and a part away from it may
        not count on the part that comes last. Each corner takes the reference on some axes and
        ``v0`` on the others."""
        n = pairs.rows.shape[1]
        if not pairs.moved.any():
            return Constraint.empty(n, _BETWEEN)
        j = pairs.base[pairs.moved]
        measured = j * np.asarray(v0, dtype=float)  # each axis's share of the approach at v₀
        # [corner, pair]: the reference's share on the corner's axes, v₀'s on the others
        base = (j * _PARTS[:, None, :]) @ pairs.to_base
        return Constraint.from_lower(*pairs.on_base(base, -(measured @ (1.0 - _PARTS).T).T), _BETWEEN)

    def after_turn(self, pairs: Pairs, v0, command, world_rates: bool) -> Constraint:
        """For each pair the base moves, the same row as the base will see it once it has turned
        on by Δθ: the pair's normal turns the other way in the base's frame (j_xy becomes
        R(−Δθ) j_xy). A lagging base turning at ω (its measured twist ``v0``) drives at its
        reference of τ ago: a reference in the world frame (``world_rates``) is driven turned by
        Δθ = ω τ. A reference held in the base's frame turns with the base, which turns on for
        its lag and then while the turn brakes at the base's limit α, whatever its reference
        asks: Δθ = ω τ + ω |ω| / (2 α), ω the faster of the measured turn and the ``command``'s.
        Without it, a reference that approaches at the bound now swings into the obstacle as the
        turn goes on (robot A passing a table's corner while it turns)."""
        axes, n = pairs.axes, pairs.rows.shape[1]
        if 2 not in axes or not pairs.moved.any():
            return Constraint.empty(n, _AFTER)
        if world_rates:
            turn = float(v0[2]) * self.lag
        else:
            omega = max(float(v0[2]), float(command[axes.index(2)]), key=abs)
            alpha = float(self.base_acceleration[2])
            turn = omega * self.lag + (omega * abs(omega) / (2.0 * alpha) if alpha > 0.0 else 0.0)
        if abs(turn) < TOLERANCE:
            return Constraint.empty(n, _AFTER)
        ahead = pairs.base[pairs.moved] @ rotation_z(turn)  # rows R(−Δθ) j: jᵀ R(Δθ)
        return Constraint.from_lower(*pairs.on_base(ahead @ pairs.to_base), _AFTER)

    def without_turn(self, pairs: Pairs) -> Constraint:
        """For each pair of the base's own body (chassis, wheels: no arm joint moves it) and an
        obstacle whose distance the base's turn changes, the same row without the turn's share,
        its bound without the turn's braking (:attr:`Pairs.turn_braking`): the base's linear
        approach brakes as the linear axes can even when the turn stops. Without
        it, a turn that swings a corner away for the moment meets the row while the base drives
        on at the obstacle faster than its linear acceleration limits can stop (and the next
        corner swings in). The arm's pairs keep the turn: the arm brakes its own share fast."""
        n = pairs.rows.shape[1]
        if 2 not in pairs.axes:
            return Constraint.empty(n, _WITHOUT)
        turning = pairs.body & (pairs.base[:, 2] != 0.0)
        if not turning.any():
            return Constraint.empty(n, _WITHOUT)
        linear = pairs.base[turning] * _LINEAR
        rows = pairs.on_base(linear @ pairs.to_base, pairs.turn_braking[turning], which=turning)
        return Constraint.from_lower(*rows, _WITHOUT)

    def turn_rate(self, pairs: Pairs, base_velocity) -> Constraint:
        """For each pair of the base's own body and an obstacle, a row on the turn rate: turning
        at ω while driving at ``v`` (the measured twist ``base_velocity``, base frame) turns the
        pair's normal under the base's velocity, which changes the approach rate n · v at ω
        (n_x v_y − n_y v_x) per second, towards the obstacle for one sign of ω. The linear axes
        must brake that as well, so the turn may take no more than :data:`TURN_SHARE` of their
        deceleration (the dampers count on the rest): a base driving past an obstacle may not
        swing its path into it faster than it can brake."""
        axes, n = pairs.axes, pairs.rows.shape[1]
        linear, slowest = linear_axes(axes, self.base_acceleration)
        if 2 not in axes or not linear or base_velocity is None:
            return Constraint.empty(n, _TURN)
        body = pairs.body
        base = pairs.base
        v = np.asarray(base_velocity, dtype=float)
        bend = base[body, 0] * v[1] - base[body, 1] * v[0]  # n_x v_y − n_y v_x
        if not bend.any():
            return Constraint.empty(n, _TURN)
        rows = np.zeros((int(body.sum()), n))
        rows[:, axes.index(2)] = -bend
        budget = TURN_SHARE * slowest * np.hypot(base[body, 0], base[body, 1])
        return Constraint.from_lower(rows, -budget, _TURN)
