"""ROS-free PyBullet simulator of a wheeled mobile manipulator: :class:`SimWorld`.

One world = one PyBullet client (``p.DIRECT`` by default, ``p.GUI`` on request); every call
passes its ``physicsClientId``, so several worlds in one process do not interfere. The
robot is loaded from the same URDF as the kinematics core (``RobotConfig.urdf_path``).

Commands follow ros2_control's ``JointGroupVelocityController``: one velocity vector per
group, held until replaced. Groups: robot A (steerable) ``arm`` (7), ``steer`` (4),
``drive`` (4); robot B (Mecanum) ``arm`` (7), ``wheel`` (4). A command of the wrong length
or with NaN/inf is rejected and never applied (the previous command stays); entries beyond
the URDF ``<limit velocity>`` are clamped to it and counted.

Base motion (``base_mode``)
---------------------------

``kinematic`` (default; fast, exact, deterministic)
    No dynamics; joints and base are placed with ``resetJointStatesMultiDof`` /
    ``resetBasePositionAndOrientation`` and ``stepSimulation`` is never called.
    Arm, steer, drive and wheel joints integrate their commanded rates exactly
    (``q += q̇ dt``; arm joints stop at their position limits, counted). The base twist
    comes from the exact rolling model of the base
    (:meth:`~wmm_control.robot_config.BaseSection.rolling_model`; robot A:
    ``SteerableGeometry.twist_from_wheels``, least squares over rolling + no-side-slip;
    robot B: Xing eq. 16 ``MecanumKinematics.twist_from_wheels``) and the pose is
    integrated with the SE(2) exponential, the twist held constant in the base frame.
    While a joint whose position the rolling model reads moves (robot A steering: the model's
    ``steered`` joints), the twist is re-evaluated at the midpoint of each of the
    ``substeps`` sub-intervals (β changes within the period; batched by the model's
    ``twists_of_joints``); otherwise one exact
    exponential covers the period. The true twist then passes through the seeded slip
    model (:mod:`sim_bridge.slip`). Limits: no contact, no tipping, no wheel-lift; a wheel
    set that violates the no-side-slip condition (inconsistent ICR) is resolved by the
    least-squares fit, not by tyre scrubbing forces; the floor is flat.

``physics`` (contact dynamics, ``substeps`` PyBullet steps per period)
    Every joint is a PyBullet velocity motor (``VELOCITY_CONTROL``) targeting the command.
    Arm motors use ``ARM_FORCE_FACTOR`` × the URDF effort (a stiff servo, so the arm follows
    its velocity command closely despite gravity); steer/drive/wheel motors use the URDF
    effort. Joint states are measured.

    * Robot A: real wheel–ground contact. The drive wheels are the URDF cylinders on a
      ``GEOM_PLANE`` floor with Coulomb friction (``WHEEL_FRICTION``); the base moves only
      through contact forces, so it scrubs, slips and lags as the steer and drive motors
      allow. The URDF is loaded with ``URDF_USE_IMPLICIT_CYLINDER``: PyBullet's default turns
      each cylinder into a convex hull, a polygonal wheel that rolls on its corners and
      carries its load on one edge at a time. With those wheels a 10 s straight run at
      0.4 m/s under zero steer rates turned the steer joints by up to 0.036 rad and yawed
      the base at −0.005 rad/s (0.053 rad, 13.5 cm off the line over 4 m). With true
      cylinders: 0.001 rad, 0.0015 rad and 1.2 cm. What remains is the velocity motors'
      residual: under a zero command the steer joints creep at about 2e-4 rad/s (arm
      joints below 7e-4 rad/s), whatever the solver iterations; a controller closing on the
      measured angles absorbs it.
    * Robot B: the URDF wheels are plain cylinders (rollers are not modelled), so plain
      contact would behave like a skid-steer car. Chosen instead: the wheel cylinders keep
      the real ground contact for *support* (normal forces from PyBullet) but with zero
      friction, and each wheel's traction is a Mecanum roller tyre model applied as an
      external force at its contact point: a roller of wheel ``i`` transmits force only
      along its axis ``a_i = (−sin γ_i, cos γ_i)`` in the base frame (γ_i the wheel's roller
      angle, :class:`~wmm_control.robot_config.MecanumBase`; for robot B fl/rr
      ``(1, −1)/√2``, fr/rl ``(1, 1)/√2``, the axes of eq. 16), the slip velocity there is
      ``s_i = a_i · (v_contact,i − R φ̇_i x̂_base)`` and the force is
      ``F_i = −clip(c s_i, ±μ N_i) a_i`` (regularised Coulomb friction, ``μ`` =
      ``WHEEL_FRICTION``, ``N_i`` the PyBullet normal force of the previous substep, ``c``
      chosen for a stable explicit step). Along the roller's rolling direction the wheel is
      free. Limits: roller inertia, roller gaps and the roller motor reaction (the tyre
      force does not load the wheel motor) are not modelled; slip appears when traction
      saturates at ``μ N_i`` (hard acceleration, lifted wheel).

    In physics mode the slip model is not applied (slip comes from contact); odometry
    is still dead reckoning from the measured wheel joint rates, once per substep.

Odometry (both modes): what a real base would report — the wheel joint rates (commanded =
applied in kinematic mode, measured in physics mode) through the nominal model, SE(2)
exponential. In kinematic mode with slip off it is computed from the very same twists as
the ground truth, so odometry and truth are bit-equal.

Frames: world z up; the ``base_link`` origin is placed at world z = 0 (robot A: on the
floor; robot B: the arm mount, the floor at ``ground_z``). PyBullet's base position is the
base's inertial (COM) frame; it is converted to and from ``base_link``.
"""

import math
from collections.abc import Iterable
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pinocchio as pin
import pybullet as p
from numpy.typing import ArrayLike

from wmm_control.errors import ConfigError
from wmm_control.kinematics.obstacles import Obstacle
from wmm_control.geometry import (
    matrix_from_quaternion,
    quaternion_from_yaw,
    se2_integrate,
    twist_to_base,
    wrap_angle,
    yaw_from_quaternion,
)
from wmm_control.resources import loadable_urdf
from wmm_control.robot_config import RobotConfig, load_robot

from sim_bridge.client import OwnedClient
from sim_bridge.collision import add_obstacle
from sim_bridge.slip import SlipModel, SlipParams

__all__ = ['SimWorld', 'CommandResult', 'BASE_MODES', 'CLAMP_TOLERANCE']

#: A command beyond its velocity limit by less than this fraction is round-off: clipped, not counted.
CLAMP_TOLERANCE = 1e-12

BASE_MODES = ('kinematic', 'physics')
GRAVITY = 9.81  # [m/s²]
WHEEL_FRICTION = 0.9  # Coulomb coefficient of wheel–floor contact [-]
SUPPORT_TOLERANCE = 0.005  # [m] a link this close to the floor at the start state rests on it (a caster)
ARM_FORCE_FACTOR = 20.0  # arm velocity-motor force = factor × URDF effort (physics mode)
SETTLE_TIME = 0.25  # [s] of zero-command physics before t = 0 (physics mode)


class CommandResult(NamedTuple):
    """Outcome of :meth:`SimWorld.set_command`.

    Attributes:
        accepted: False when the command was rejected (nothing applied).
        clamped: number of entries clamped to the velocity limit [-].
        reason: empty when accepted unclamped; else what happened.
    """

    accepted: bool
    clamped: int
    reason: str


class SimWorld(OwnedClient):
    """A wheeled mobile manipulator in its own PyBullet world.

    Args:
        robot: ``'steerable'``/``'A'``, ``'mecanum'``/``'B'``, a robot YAML path, or a
            :class:`~wmm_control.robot_config.RobotConfig`.
        base_mode: ``'kinematic'`` or ``'physics'`` (see the module docstring).
        dt: simulation period advanced by :meth:`step` [s], > 0.
        substeps: sub-intervals per period (physics steps; rolling-model evaluations while
            steering in kinematic mode) [-], >= 1.
        slip: :class:`~sim_bridge.slip.SlipParams` or ``None`` (no slip; kinematic mode only).
        seed: seed of the slip noise when ``slip.seed`` is ``None`` [-].
        gui: open a PyBullet GUI window instead of ``p.DIRECT``.
        start_base_pose: (x, y, θ) [m, m, rad]; default the robot's ``start.base_pose``.
        start_arm: arm joint positions [rad or m], shape (n,); default ``start.arm``.
        obstacles: :class:`~wmm_control.kinematics.obstacles.Obstacle` s, static bodies in
            the world (:meth:`set_obstacles` changes them; :meth:`obstacle_clearance` measures).

    Attributes:
        robot: the :class:`~wmm_control.robot_config.RobotConfig`.
        dt: period of :meth:`step` [s]; ``time``: simulated time since the start [s].
        command_groups: group name -> tuple of joint names (command order).
        joint_names: every simulated joint, arm then steer + drive (A) or wheels (B).
        held_joint_names: the joints outside the arm and the base (head, fingers), held where
            the robot YAML's ``held_joints`` puts them (:meth:`held_joint_state`).
        velocity_limits: URDF velocity limit per joint of ``joint_names`` [rad/s]. Shape (n,).
        counters: ``{group: {'clamped': entries clamped, 'rejected': commands rejected,
            'position_limited': arm joint-steps stopped at a position limit}}``.

    Raises:
        ConfigError: unknown robot or mode, bad ``dt``/``substeps``/start state, slip in
            physics mode, or a joint or link of the robot description missing from the URDF.
    """

    def __init__(
        self,
        robot: str | Path | RobotConfig,
        base_mode: str = 'kinematic',
        dt: float = 0.025,
        substeps: int = 10,
        slip: SlipParams | None = None,
        seed: int = 0,
        gui: bool = False,
        start_base_pose: ArrayLike | None = None,
        start_arm: ArrayLike | None = None,
        obstacles: Iterable[Obstacle] = (),
    ):
        self.robot = robot if isinstance(robot, RobotConfig) else load_robot(robot)
        if base_mode not in BASE_MODES:
            raise ConfigError(f'base_mode: expected one of {BASE_MODES}, got {base_mode!r}')
        dt = float(dt)
        if not (math.isfinite(dt) and dt > 0.0):
            raise ConfigError(f'dt must be finite and > 0 [s], got {dt}')
        if int(substeps) != substeps or substeps < 1:
            raise ConfigError(f'substeps must be an integer >= 1, got {substeps!r}')
        self.base_mode = base_mode
        self.dt = dt
        self.substeps = int(substeps)
        self.time = 0.0
        self._h = dt / self.substeps
        self._slip = SlipModel(slip, seed)
        if base_mode == 'physics' and not self._slip.off:
            raise ConfigError(
                'slip: the slip model applies to base_mode "kinematic" only; '
                'in "physics" mode slip comes from the wheel contact'
            )
        cfg = self.robot
        base = cfg.base
        # the rolling model of the base: its twist of the base's joints (their positions it reads,
        # ``steered``: the steer angles, and their rates)
        self._geom = base.rolling_model()
        # wheels that drive through free rollers (Mecanum): the tyre model of physics mode
        self._roller = base.roller_axes.tolist()
        self._tyre = bool(self._roller)
        self.command_groups = {'arm': tuple(cfg.arm.joints), **base.command_groups}
        self._r_wheel = base.wheel_radius
        self.joint_names = tuple(n for g in self.command_groups.values() for n in g)
        self._slices = {}
        start = 0
        for g, names in self.command_groups.items():
            self._slices[g] = slice(start, start + len(names))
            start += len(names)
        self._n = start
        # the base's joints (after the arm's, in its command order) and of them the rolling ones
        self._base = slice(self._slices['arm'].stop, self._n)
        self._rolling = [self.joint_names.index(name) for name in base.rolling_joints]
        self.counters = {g: {'clamped': 0, 'rejected': 0, 'position_limited': 0} for g in self.command_groups}
        self._cmd = np.zeros(self._n)

        base0 = cfg.start.base_pose if start_base_pose is None else start_base_pose
        arm0 = cfg.start.arm if start_arm is None else start_arm
        base0 = self._start_vector(base0, 3, 'start_base_pose')
        arm0 = self._start_vector(arm0, len(cfg.arm.joints), 'start_arm')
        self._q = np.zeros(self._n)
        self._q[self._slices['arm']] = arm0
        self._qd = np.zeros(self._n)
        self._pose = (float(base0[0]), float(base0[1]), float(base0[2]))
        self._odom = self._pose
        self._twist = (0.0, 0.0, 0.0)
        self._odom_twist = (0.0, 0.0, 0.0)
        self.rim_speed = 0.0  # [m/s] mean absolute rim speed of the last period (kinematic mode)
        self._twist_cache = None
        self.obstacles: tuple[Obstacle, ...] = ()
        self._obstacle_ids: list[int] = []

        self._cid = p.connect(p.GUI if gui else p.DIRECT)
        if self._cid < 0:
            raise ConfigError('could not connect to PyBullet (a GUI is already open in this process?)')
        try:
            self._build()
            self.set_obstacles(obstacles)
        except Exception:
            p.disconnect(physicsClientId=self._cid)
            self._cid = -1
            raise

    # ------------------------------------------------------------------ setup
    @staticmethod
    def _start_vector(value, size, name):
        arr = np.asarray(value, dtype=float)
        if arr.shape != (size,) or not np.all(np.isfinite(arr)):
            raise ConfigError(f'{name}: expected {size} finite numbers, got {value!r}')
        return arr

    def _build(self):
        cid, cfg = self._cid, self.robot
        p.resetSimulation(physicsClientId=cid)
        p.setGravity(0.0, 0.0, -GRAVITY, physicsClientId=cid)
        p.setPhysicsEngineParameter(
            fixedTimeStep=self._h, numSubSteps=0, deterministicOverlappingPairs=1, physicsClientId=cid
        )
        # Floor: an infinite collision plane at ground_z, drawn as a large thin box.
        plane = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=cid)
        vis = p.createVisualShape(
            p.GEOM_BOX,
            halfExtents=[15.0, 15.0, 0.005],
            visualFramePosition=[0.0, 0.0, -0.005],
            rgbaColor=[0.82, 0.84, 0.80, 1.0],
            physicsClientId=cid,
        )
        self.ground_id = p.createMultiBody(0.0, plane, vis, basePosition=[0.0, 0.0, cfg.ground_z], physicsClientId=cid)
        # Implicit cylinders: by default PyBullet turns a URDF cylinder into a convex hull, a
        # polygonal wheel that rolls on its corners (see the module docstring, physics mode).
        self.body_id = p.loadURDF(
            str(loadable_urdf(cfg.urdf_path, cfg.package_dirs)),
            basePosition=[0.0, 0.0, 0.0],
            flags=p.URDF_USE_INERTIA_FROM_FILE | p.URDF_USE_IMPLICIT_CYLINDER,
            physicsClientId=cid,
        )
        body = self.body_id

        joints, links = {}, {}
        urdf_vel = {}
        for j in range(p.getNumJoints(body, physicsClientId=cid)):
            info = p.getJointInfo(body, j, physicsClientId=cid)
            name = info[1].decode()
            joints[name] = j
            links[info[12].decode()] = j
            urdf_vel[name] = (float(info[11]), float(info[10]))  # max velocity, max force
        missing = [n for n in self.joint_names if n not in joints]
        if missing:
            raise ConfigError(f'{cfg.urdf_path.name}: joints {missing} not found; URDF has {sorted(joints)}')
        if cfg.ee_frame not in links:
            raise ConfigError(f'{cfg.urdf_path.name}: ee frame {cfg.ee_frame!r} not found; links {sorted(links)}')
        self._ee_link = links[cfg.ee_frame]
        self._idx = [joints[n] for n in self.joint_names]
        #: the joints outside the arm and the base, held where the robot YAML puts them
        self.held_joint_names = tuple(cfg.held_joints)
        missing = [n for n in self.held_joint_names if n not in joints]
        if missing:
            raise ConfigError(f'{cfg.urdf_path.name}: held joints {missing} not found; URDF has {sorted(joints)}')
        self._held_idx = [joints[n] for n in self.held_joint_names]
        self._held_q = [cfg.held_joints[n] for n in self.held_joint_names]
        for j, value in zip(self._held_idx, self._held_q):
            p.resetJointState(body, j, value, 0.0, physicsClientId=cid)
        yaml_vel = cfg.joint_velocity_limits
        # URDF <limit velocity> is authoritative; the YAML value covers a URDF without one.
        self.velocity_limits = np.array(
            [urdf_vel[n][0] if urdf_vel[n][0] > 0.0 else yaml_vel[n] for n in self.joint_names]
        )
        efforts = np.array([urdf_vel[n][1] for n in self.joint_names])
        self._lower = np.full(self._n, -np.inf)
        self._upper = np.full(self._n, np.inf)
        self._lower[self._slices['arm']] = cfg.arm.position_lower
        self._upper[self._slices['arm']] = cfg.arm.position_upper
        arm0 = self._q[self._slices['arm']]
        if np.any(arm0 < self._lower[self._slices['arm']]) or np.any(arm0 > self._upper[self._slices['arm']]):
            raise ConfigError(f'start_arm outside the position limits: {arm0.tolist()}')

        # base_link <-> PyBullet base (inertial/COM) frame.
        dyn = p.getDynamicsInfo(body, -1, physicsClientId=cid)
        self._com_local = pin.XYZQUATToSE3(np.array([*dyn[3], *dyn[4]]))
        self._com_identity = max(abs(v) for v in dyn[3]) < 1e-12 and abs(abs(dyn[4][3]) - 1.0) < 1e-12
        self._com_inv = p.invertTransform(dyn[3], dyn[4])

        self._wheel_links = [joints[n] for n in cfg.base.rolling_joints]

        if self.base_mode == 'kinematic':
            # Nothing is simulated dynamically: switch the default motors off.
            p.setJointMotorControlArray(
                body, self._idx, p.VELOCITY_CONTROL, forces=[0.0] * self._n, physicsClientId=cid
            )
            self._place()
        else:
            self._setup_physics(efforts)

    def set_obstacles(self, obstacles: Iterable[Obstacle]) -> None:
        """Replace the world's obstacles (:class:`~wmm_control.kinematics.obstacles.Obstacle`)."""
        for body in self._obstacle_ids:
            p.removeBody(body, physicsClientId=self._cid)
        self.obstacles = tuple(obstacles)
        self._obstacle_ids = [add_obstacle(o, self._cid) for o in self.obstacles]
        self._link_names: dict[int, str] | None = None

    def obstacle_clearance(self, reach: float = 1.0) -> tuple[float, str, str]:
        """The robot's closest approach to an obstacle, on the simulator's shapes and the true
        pose: ``(distance [m], link, obstacle)``, negative when they overlap; ``(inf, '', '')``
        when no obstacle is within ``reach`` [m]."""
        cid = self._cid
        if self._link_names is None:
            self._link_names = {-1: p.getBodyInfo(self.body_id, physicsClientId=cid)[0].decode()}
            for j in range(p.getNumJoints(self.body_id, physicsClientId=cid)):
                self._link_names[j] = p.getJointInfo(self.body_id, j, physicsClientId=cid)[12].decode()
        best = (math.inf, '', '')
        for body, obstacle in zip(self._obstacle_ids, self.obstacles):
            for point in p.getClosestPoints(self.body_id, body, reach, physicsClientId=cid):
                if point[8] < best[0]:
                    best = (float(point[8]), self._link_names[point[3]], obstacle.name)
        return best

    def _setup_physics(self, efforts):
        cid, body = self._cid, self.body_id
        arm = self._slices['arm']
        forces = efforts.copy()
        forces[arm] *= ARM_FORCE_FACTOR
        forces[forces <= 0.0] = 1e3
        self._forces = forces.tolist()
        tyre = self._tyre
        p.changeDynamics(self.ground_id, -1, lateralFriction=1.0, physicsClientId=cid)
        wheels = set(self._wheel_links)
        for j in range(p.getNumJoints(body, physicsClientId=cid)):
            # a passive support (a caster: any link but the driven wheels that rests on the
            # floor at the start state) rolls freely: no friction
            lowest = p.getAABB(body, j, physicsClientId=cid)[0][2]
            if j not in wheels and lowest <= self.robot.ground_z + SUPPORT_TOLERANCE:
                p.changeDynamics(
                    body, j, lateralFriction=0.0, rollingFriction=0.0, spinningFriction=0.0, physicsClientId=cid
                )
        for link in self._wheel_links:
            p.changeDynamics(
                body,
                link,
                lateralFriction=0.0 if tyre else WHEEL_FRICTION,
                rollingFriction=0.0,
                spinningFriction=0.0,
                physicsClientId=cid,
            )
        for j in range(-1, p.getNumJoints(body, physicsClientId=cid)):
            p.changeDynamics(body, j, linearDamping=0.0, angularDamping=0.0, physicsClientId=cid)
        if tyre:
            mass = sum(
                p.getDynamicsInfo(body, j, physicsClientId=cid)[0]
                for j in range(-1, p.getNumJoints(body, physicsClientId=cid))
            )
            # Regularised Coulomb: damping c with 4 c h / m = 0.25 keeps the explicit step stable.
            self._tyre_c = 0.25 * mass / (4.0 * self._h)
        self._place()
        zero = [0.0] * self._n
        p.setJointMotorControlArray(
            body, self._idx, p.VELOCITY_CONTROL, targetVelocities=zero, forces=self._forces, physicsClientId=cid
        )
        if self._held_idx:  # the joints outside the arm and the base: position servos where they are held
            held_efforts = [p.getJointInfo(body, j, physicsClientId=cid)[10] for j in self._held_idx]
            p.setJointMotorControlArray(
                body,
                self._held_idx,
                p.POSITION_CONTROL,
                targetPositions=self._held_q,
                forces=[ARM_FORCE_FACTOR * f if f > 0.0 else 1e3 for f in held_efforts],
                physicsClientId=cid,
            )
        for _ in range(int(round(SETTLE_TIME / self._h))):
            self._physics_substep(np.zeros(self._n), odometry=False)
        self._read_physics()
        self._qd[:] = 0.0
        self._odom = self._pose

    # ------------------------------------------------------------------ placing / reading
    def _com_pose(self, pose):
        """(position, quaternion) in the world of PyBullet's base frame (the COM's) at the planar base pose."""
        x, y, th = pose
        qz = quaternion_from_yaw(th)
        if self._com_identity:
            return (x, y, 0.0), qz.tolist()
        # The base pose, then the COM in it (p.multiplyTransforms is the same in single precision).
        com = pin.SE3ToXYZQUAT(pin.XYZQUATToSE3(np.array([x, y, 0.0, *qz])) * self._com_local)
        return com[:3].tolist(), com[3:].tolist()

    def _place(self):
        """Write the kinematic state (base pose, joint positions and rates) into PyBullet."""
        pos, orn = self._com_pose(self._pose)
        p.resetBasePositionAndOrientation(self.body_id, pos, orn, physicsClientId=self._cid)
        p.resetJointStatesMultiDof(
            self.body_id,
            self._idx,
            [[v] for v in self._q.tolist()],
            targetVelocities=[[v] for v in self._qd.tolist()],
            physicsClientId=self._cid,
        )

    def _base_link_pose(self):
        pos, orn = p.getBasePositionAndOrientation(self.body_id, physicsClientId=self._cid)
        if not self._com_identity:
            pos, orn = p.multiplyTransforms(pos, orn, self._com_inv[0], self._com_inv[1])
        return pos, orn

    def _read_physics(self):
        """Measured joint states, base pose and base twist from PyBullet (physics mode)."""
        cid, body = self._cid, self.body_id
        states = p.getJointStates(body, self._idx, physicsClientId=cid)
        self._q = np.array([s[0] for s in states])
        self._qd = np.array([s[1] for s in states])
        pos, orn = self._base_link_pose()
        th = yaw_from_quaternion(orn)
        self._pose = (pos[0], pos[1], th)
        lin, ang = p.getBaseVelocity(body, physicsClientId=cid)
        com_pos, _ = p.getBasePositionAndOrientation(body, physicsClientId=cid)
        # Linear velocity of the base_link origin (differs from the COM's when they differ).
        rx, ry = pos[0] - com_pos[0], pos[1] - com_pos[1]
        vx_w = lin[0] - ang[2] * ry
        vy_w = lin[1] + ang[2] * rx
        self._twist = tuple(twist_to_base(th, (vx_w, vy_w, ang[2])).tolist())

    # ------------------------------------------------------------------ commands
    def set_command(self, group: str, values: ArrayLike) -> CommandResult:
        """Set the velocity command of one group; it holds until replaced.

        Args:
            group: a key of :attr:`command_groups`.
            values: joint velocities [rad/s], in the group's joint order. Shape (n_group,).

        Returns:
            :class:`CommandResult`. Rejected (nothing applied, previous command kept): unknown
            group, wrong length, non-numeric, NaN or inf. Entries beyond the URDF velocity
            limit are clamped to ±limit; their number is returned and added to
            ``counters[group]['clamped']``.
        """
        if group not in self.command_groups:
            return CommandResult(False, 0, f'unknown group {group!r}; groups: {sorted(self.command_groups)}')
        sl = self._slices[group]
        n = sl.stop - sl.start
        try:
            arr = np.asarray(values, dtype=float)
        except (TypeError, ValueError):
            self.counters[group]['rejected'] += 1
            return CommandResult(False, 0, f'{group}: not a list of numbers: {values!r}')
        if arr.shape != (n,):
            self.counters[group]['rejected'] += 1
            return CommandResult(False, 0, f'{group}: expected {n} values, got shape {arr.shape}')
        if not np.all(np.isfinite(arr)):
            self.counters[group]['rejected'] += 1
            bad = np.flatnonzero(~np.isfinite(arr)).tolist()
            return CommandResult(False, 0, f'{group}: non-finite values at indices {bad}')
        lim = self.velocity_limits[sl]
        # at the limit to round-off (a controller's command exactly at it) is not counted
        over = np.abs(arr) > lim * (1.0 + CLAMP_TOLERANCE)
        clamped = int(np.count_nonzero(over))
        arr = np.clip(arr, -lim, lim)
        if clamped:
            self.counters[group]['clamped'] += clamped
            names = [self.command_groups[group][i] for i in np.flatnonzero(over)]
            reason = f'{group}: {clamped} value(s) clamped to the velocity limit: {names}'
        else:
            reason = ''
        self._cmd[sl] = arr
        return CommandResult(True, clamped, reason)

    def zero_command(self, group: str) -> CommandResult:
        """Command zero velocity to every joint of ``group`` (always accepted)."""
        if group not in self.command_groups:
            return CommandResult(False, 0, f'unknown group {group!r}; groups: {sorted(self.command_groups)}')
        self._cmd[self._slices[group]] = 0.0
        return CommandResult(True, 0, '')

    @property
    def command(self) -> np.ndarray:
        """The velocity command in force [rad/s], in :attr:`joint_names` order. Shape (n,)."""
        return self._cmd.copy()

    # ------------------------------------------------------------------ stepping
    def step(self) -> None:
        """Advance the world by :attr:`dt` under the commands in force."""
        if self.base_mode == 'kinematic':
            self._step_kinematic()
        else:
            self._physics_step()
        self.time += self.dt

    def _nominal_twists(self, vel):
        """Nominal base twists (one per sub-interval, or one for the whole period).

        Returns:
            (list of (twist, duration)), mean absolute rim speed [m/s].
        """
        geom, base = self._geom, self._base
        q0, rates = self._q[base], vel[base]
        rim = self._r_wheel * float(np.mean(np.abs(vel[self._rolling])))
        if not rates[geom.steered].any():  # the positions the twist reads stay: one twist
            key = (q0[geom.steered].tobytes(), rates.tobytes())
            if self._twist_cache is None or self._twist_cache[0] != key:
                self._twist_cache = (key, tuple(geom.twist_of_joints(q0, rates).tolist()))
            return [(self._twist_cache[1], self.dt)], rim
        h = self._h
        positions = q0 + np.outer((np.arange(self.substeps) + 0.5) * h, rates)
        return [(tuple(tw), h) for tw in geom.twists_of_joints(positions, rates).tolist()], rim

    def _step_kinematic(self):
        vel = self._cmd.copy()
        q_new = self._q + vel * self.dt
        arm = self._slices['arm']
        qa = q_new[arm]
        lo, hi = self._lower[arm], self._upper[arm]
        hit = (qa < lo) | (qa > hi)
        if hit.any():
            self.counters['arm']['position_limited'] += int(np.count_nonzero(hit))
            qa_c = np.clip(qa, lo, hi)
            va = vel[arm]
            va[hit] = (qa_c[hit] - self._q[arm][hit]) / self.dt
            vel[arm] = va
            q_new[arm] = qa_c
        segments, rim = self._nominal_twists(vel)
        pose, odom = self._pose, self._odom
        slip = self._slip
        if slip.off:
            for tw, h in segments:
                odom = se2_integrate(odom, tw, h)
            pose, true_tw = odom, segments[-1][0]
        else:
            keep, bias = slip.sample(rim)
            for tw, h in segments:
                odom = se2_integrate(odom, tw, h)
                true_tw = (keep * tw[0] + bias[0], keep * tw[1] + bias[1], keep * tw[2] + bias[2])
                pose = se2_integrate(pose, true_tw, h)
        self._q, self._qd = q_new, vel
        self._pose, self._odom = pose, odom
        self._twist, self._odom_twist = true_tw, segments[-1][0]
        self.rim_speed = rim
        self._place()

    def _physics_substep(self, vel, odometry=True):
        cid, body = self._cid, self.body_id
        if self._tyre:  # the roller tyre model of Mecanum wheels
            self._apply_tyre_forces()
        p.stepSimulation(physicsClientId=cid)
        if odometry:
            states = p.getJointStates(body, self._idx, physicsClientId=cid)
            q = [s[0] for s in states]
            qd = [s[1] for s in states]
            tw = tuple(self._geom.twist_of_joints(q[self._base], qd[self._base]).tolist())
            self._odom = se2_integrate(self._odom, tw, self._h)
            self._odom_twist = tw

    def _physics_step(self):
        vel = self._cmd.tolist()
        p.setJointMotorControlArray(
            self.body_id,
            self._idx,
            p.VELOCITY_CONTROL,
            targetVelocities=vel,
            forces=self._forces,
            physicsClientId=self._cid,
        )
        for _ in range(self.substeps):
            self._physics_substep(vel)
        self._read_physics()

    def _apply_tyre_forces(self):
        """Mecanum roller traction at each wheel's contact point (robot B, physics mode)."""
        cid, body = self._cid, self.body_id
        normal = [0.0] * len(self._wheel_links)
        for c in p.getContactPoints(bodyA=body, bodyB=self.ground_id, physicsClientId=cid):
            if c[3] in self._wheel_links:
                normal[self._wheel_links.index(c[3])] += c[9]
        pos, orn = p.getBasePositionAndOrientation(body, physicsClientId=cid)
        lin, ang = p.getBaseVelocity(body, physicsClientId=cid)
        xb, yb = matrix_from_quaternion(orn)[:, :2].T.tolist()  # the base's x and y axes
        states = p.getJointStates(
            body,
            [self._idx[i] for i in self._rolling],
            physicsClientId=cid,
        )
        links = p.getLinkStates(body, self._wheel_links, physicsClientId=cid)
        r = self._r_wheel
        for i in range(len(normal)):
            if normal[i] <= 0.0:
                continue
            cx, cy, cz = links[i][4]
            pc = (cx, cy, cz - r)
            dx, dy, dz = pc[0] - pos[0], pc[1] - pos[1], pc[2] - pos[2]
            vcx = lin[0] + ang[1] * dz - ang[2] * dy
            vcy = lin[1] + ang[2] * dx - ang[0] * dz
            rim = r * states[i][1]
            ax_b, ay_b = self._roller[i]
            ax = ax_b * xb[0] + ay_b * yb[0]
            ay = ax_b * xb[1] + ay_b * yb[1]
            slip = ax * (vcx - rim * xb[0]) + ay * (vcy - rim * xb[1])
            cap = WHEEL_FRICTION * normal[i]
            f = -max(-cap, min(cap, self._tyre_c * slip))
            p.applyExternalForce(body, -1, [f * ax, f * ay, 0.0], pc, p.WORLD_FRAME, physicsClientId=cid)

    # ------------------------------------------------------------------ state
    def joint_state(self) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
        """Every simulated movable joint: arm, then steer + drive (A) or wheels (B).

        Returns:
            (names tuple, positions [rad] shape (n,), velocities [rad/s] shape (n,)); the
            velocities are the rates applied in the last step (measured in physics mode).
        """
        return self.joint_names, self._q.copy(), self._qd.copy()

    def held_joint_state(self) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
        """The joints outside the arm and the base (head, fingers; :attr:`held_joint_names`),
        where the robot YAML holds them (``held_joints``): placed there in kinematic mode,
        position servos in physics mode.

        Returns:
            (names tuple, positions [rad or m] shape (h,), velocities [rad/s or m/s] shape (h,)),
            as PyBullet has them.
        """
        states = p.getJointStates(self.body_id, self._held_idx, physicsClientId=self._cid) if self._held_idx else []
        return (
            self.held_joint_names,
            np.array([s[0] for s in states], dtype=float),
            np.array([s[1] for s in states], dtype=float),
        )

    def base_pose(self) -> np.ndarray:
        """True base_link pose (x, y, θ) in world [m, m, rad], θ in [−π, π]. Shape (3,)."""
        return np.array([self._pose[0], self._pose[1], wrap_angle(self._pose[2])])

    def base_twist(self) -> np.ndarray:
        """True base twist (vx, vy, ω) in the base frame [m/s, m/s, rad/s]. Shape (3,)."""
        return np.array(self._twist)

    def odom_pose(self) -> np.ndarray:
        """Wheel-odometry pose (x, y, θ) [m, m, rad], θ in [−π, π]; starts at the start pose. Shape (3,)."""
        return np.array([self._odom[0], self._odom[1], wrap_angle(self._odom[2])])

    @property
    def slip(self) -> SlipModel:
        """The :class:`~sim_bridge.slip.SlipModel` of the kinematic base (off in physics mode)."""
        return self._slip

    def odom_twist(self) -> np.ndarray:
        """Wheel-odometry twist (vx, vy, ω) in the base frame [m/s, m/s, rad/s]. Shape (3,)."""
        return np.array(self._odom_twist)

    def ee_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Ground-truth end-effector pose in world (the ee link frame, not its COM frame).

        Returns:
            (position [m] shape (3,), quaternion (x, y, z, w) shape (4,)).
        """
        st = p.getLinkState(self.body_id, self._ee_link, computeForwardKinematics=1, physicsClientId=self._cid)
        return np.array(st[4]), np.array(st[5])

    @property
    def client_id(self) -> int:
        """The PyBullet physics client id of this world (-1 once closed)."""
        return self._cid
