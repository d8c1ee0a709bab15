"""Kinematic model of a wheeled mobile manipulator, on pinocchio.

The generalized coordinates are ``q = (x_b, y_b, θ_b, q_m)``: the planar base pose in
the world frame followed by the n arm joints (Xing eq 2). The other joints of the URDF are
locked out of this model: the wheel-side joints (steer, drive, Mecanum wheels) at zero, since
they do not move the end effector, and the joints outside the arm and the base (head, fingers)
at the positions the robot holds them at (:attr:`RobotConfig.held_joints`;
:func:`held_configuration` gives the configuration of any pinocchio model of the robot's URDF
with them there).

Quantities (Sorour §II, Xing §2 and appendices A–B):

* end-effector pose in the base and world frames;
* ``J_a``: arm geometric Jacobian in the base frame (Sorour eq 1). Shape (6, 7);
* ``H``: the base-to-end-effector velocity map of Sorour eq (4). Shape (6, 6);
* ``J_mm = M_RPY [H J_b, J_a]`` (eq 7), with ``M_RPY = blockdiag(I, Ω⁻¹)``, the RPY rates
  of the base-frame end-effector orientation. Shape (6, 6 + n);
* ``J``: world-frame Jacobian over ``q`` (Xing eq 2) and ``J̇q̇`` (eq 4). Shapes (6, 3 + n), (6,);
* ``J_m``: the arm's columns of that world Jacobian (position rows, or all six), whose
  manipulability the tasks measure (:mod:`wmm_control.kinematics.tasks`).

Usage::

    model = KinematicModel('steerable')
    model.update(base_pose, q_arm)           # one FK + Jacobian pass (data.oMi, data.J)
    pos, rot = model.ee_placement_world()
    ja = model.arm_jacobian_base()
"""

import threading
from collections import OrderedDict
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Self

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from wmm_control.checks import as_finite_vector
from wmm_control.errors import ConfigError, UnknownFrameError, WmmError
from wmm_control.geometry import continuous_to_q, rpy_from_matrix, rpy_rate_map, set_joint_position
from wmm_control.robot_config import RobotConfig, held_joint_positions, load_robot
from wmm_control.urdf import UrdfTree

__all__ = ['KinematicModel', 'pinocchio_model', 'held_configuration', 'N_BASE', 'ARM_ROWS', 'arm_rows']

N_BASE = 3
_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
#: the rows of the arm Jacobian J_m: its position rows, or all six
ARM_ROWS = {'position': slice(0, 3), 'full': slice(0, 6)}


def pinocchio_model(urdf_path: str | Path, planar_root: bool = True) -> pin.Model:
    """The pinocchio model of a URDF, parsed once per process and shared by every caller.

    With ``planar_root``, its root joint is a planar (x, y, θ) one made of PX, PY and RZ: the
    composite keeps ``q`` and ``v`` equal to (x, y, θ) and their world-frame rates, unlike
    pinocchio's planar joint (cos/sin in q, body-frame velocity); without, the URDF's root
    link is fixed. Callers with the same URDF text and option get the same object (the process's
    store of models: :func:`_shared`), so it is read-only: no caller edits its joints, limits
    or frames, and each keeps its own ``pin.Data`` (``model.createData()``).

    Raises:
        ConfigError: the file cannot be read or pinocchio cannot load it.
    """
    return _parsed(urdf_path, planar_root)[1]


def _parsed(urdf_path, planar_root):
    """(the store's key, the model) of :func:`pinocchio_model`: the model is parsed from the
    text the key holds, so that a URDF rewritten in the process is parsed again."""
    try:
        text = Path(urdf_path).read_text(encoding='utf-8')
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f'pinocchio could not load {urdf_path}: {exc}') from exc

    def parse():
        try:
            if not planar_root:
                return pin.buildModelFromXML(text)
            root = pin.JointModelComposite()
            root.addJoint(pin.JointModelPX())
            root.addJoint(pin.JointModelPY())
            root.addJoint(pin.JointModelRZ())
            return pin.buildModelFromXML(text, root)
        except (RuntimeError, ValueError) as exc:
            raise ConfigError(f'pinocchio could not load {urdf_path}: {exc}') from exc

    key = ('urdf', text, bool(planar_root))
    return key, _shared(key, parse)


#: the most models the process keeps: the least recently asked for is dropped beyond it (its
#: users keep it; the next user of its description gets a new parse)
SHARED_MODELS = 32
_store: OrderedDict[tuple, pin.Model] = OrderedDict()
_store_lock = threading.Lock()


def _shared(key: tuple, build: Callable[[], pin.Model]) -> pin.Model:
    """The process's one model for ``key`` (the inputs that make it: a URDF's text and options,
    a reduction's locked joints and positions), made by ``build()`` the first time, under a lock:
    the planner builds its models in its own thread.

    Sharing a ``pin.Model`` is safe because nothing in the package writes to one after it is
    built: the kinematics, collision and planning code take it as pinocchio's algorithms do
    (``const Model&``), each user with its own ``pin.Data`` and ``pin.GeometryData``, so two
    threads read one model at once. A user that needs a changed model (other locked joints,
    held positions) gets another entry; geometry a user adds (the floor, obstacles) goes to a
    ``pin.GeometryModel`` of its own (:meth:`KinematicModel.reduce_geometry` returns a new one
    each call), never to the shared model.
    """
    with _store_lock:
        model = _store.get(key)
        if model is None:
            model = _store[key] = build()
            if len(_store) > SHARED_MODELS:
                _store.popitem(last=False)
        else:
            _store.move_to_end(key)
        return model


def held_configuration(model: pin.Model, held: Mapping[str, float]) -> np.ndarray:
    """The configuration of ``model`` (a pinocchio model of the robot's URDF, with or without the
    planar base joint) with every joint of ``held`` at its position [rad or m], the others at
    pinocchio's neutral (zero; a continuous joint at angle 0).

    Raises:
        ConfigError: a joint of ``held`` is not a one-number joint of ``model``.
    """
    q = pin.neutral(model)
    for name, value in held.items():
        joint = model.joints[model.getJointId(name)] if model.existJointName(name) else None
        if joint is None or joint.nv != 1:
            raise ConfigError(f'held joint {name!r} is not a one-number joint of {model.name}')
        set_joint_position(q, joint.idx_q, joint.nq, float(value))
    return q


class KinematicModel:
    """Kinematics of one robot: base pose + n arm joints → end effector.

    One configuration of the robot: every object of one robot in a process (a method's, the
    planner's, the markers') reads the same pinocchio models, :attr:`full_model` and
    :attr:`model` (:func:`pinocchio_model`, read-only), and keeps its own :attr:`data` and
    state, so that each sets its own configuration, in its own thread.

    Args:
        robot: robot name (``'steerable'``/``'A'``, ``'mecanum'``/``'B'``), YAML path, or
            a loaded :class:`RobotConfig`.
        ee_frame: end-effector frame name; defaults to the robot's ``ee_frame``.

    Raises:
        ConfigError: the robot files are invalid or the arm joints are not in the URDF.
        UnknownFrameError: ``ee_frame`` is not a frame of the URDF.
    """

    def __init__(self, robot: str | Path | RobotConfig, ee_frame: str | None = None) -> None:
        self.config = robot if isinstance(robot, RobotConfig) else load_robot(robot)
        cfg = self.config
        self._build(cfg.urdf_path, cfg.arm.joints, ee_frame or cfg.ee_frame, cfg.base_link, cfg.held_joints)

    @classmethod
    def from_urdf(
        cls,
        urdf_path: str | Path,
        arm_joints: Iterable[str],
        ee_frame: str,
        base_link: str,
        held: Mapping[str, float] | None = None,
    ) -> Self:
        """A model of a URDF alone, before any robot YAML exists (``config`` is None).

        Args:
            urdf_path: the URDF.
            arm_joints: the arm joint names, root first.
            ee_frame, base_link: frame names.
            held: [rad or m] the joints outside the arm at the positions they are held at;
                None: their defaults (:func:`~wmm_control.robot_config.held_joint_positions`).
        """
        self = cls.__new__(cls)
        # A model of a URDF alone has no robot YAML; everywhere else the package builds its
        # models from one and reads ``config`` as a RobotConfig.
        self.config = None  # type: ignore[assignment]
        arm_joints = tuple(arm_joints)
        if held is None:
            held = held_joint_positions(UrdfTree(urdf_path), arm_joints)
        self._build(urdf_path, arm_joints, ee_frame, base_link, held)
        return self

    def _build(self, urdf_path, arm_names, ee_frame, base_link, held):
        # the process's shared models (:func:`_shared`), ``data`` this object's own
        full_key, self.full_model = _parsed(urdf_path, True)
        missing = [n for n in arm_names if not self.full_model.existJointName(n)]
        if missing:
            raise ConfigError(f'arm joints {missing} are not in {Path(urdf_path).name}')
        locked = [
            self.full_model.getJointId(n) for n in self.full_model.names[1:] if n not in arm_names and n != 'root_joint'
        ]
        self._locked = locked
        self._held_q = held_q = held_configuration(self.full_model, held)
        self.model = _shared(
            ('reduced', full_key, tuple(locked), held_q.tobytes()),
            lambda: pin.buildReducedModel(self.full_model, locked, held_q),
        )
        self.data = self.model.createData()
        names = list(self.model.names[2:])
        if names != list(arm_names):
            raise ConfigError(f'arm joints must form one chain in the order {list(arm_names)}, the URDF gives {names}')
        for jid in range(2, self.model.njoints):
            if self.model.joints[jid].nv != 1:
                raise ConfigError(f'arm joint {self.model.names[jid]} is not a 1-DOF joint')
        self.n_arm = len(arm_names)
        self.nv = N_BASE + self.n_arm
        self._arm_joint_ids = list(range(2, self.model.njoints))
        self._continuous = [(j.idx_q, j.idx_v) for j in self.model.joints[2:] if j.nq == 2]
        self._plain = [(j.idx_q, j.idx_v) for j in self.model.joints[2:] if j.nq == 1]
        self._cont_q = np.array([iq for iq, _ in self._continuous], dtype=int)
        self._cont_v = np.array([iv for _, iv in self._continuous], dtype=int)
        self._plain_q = np.array([iq for iq, _ in self._plain], dtype=int)
        self._plain_v = np.array([iv for _, iv in self._plain], dtype=int)
        self.ee_frame = ee_frame
        self._ee_id = self.frame_id(self.ee_frame)
        self._base_id = self.frame_id(base_link)
        self._q = pin.neutral(self.model)
        self._q_flat = None
        self._v = None
        self._valid = False
        #: how many times :meth:`update` has run: what was computed from ``data`` holds while it stays
        self.revision = 0
        self._jac = np.zeros((6, self.nv))

    # ------------------------------------------------------------------ frames
    @property
    def frame_names(self) -> list[str]:
        """Names of every frame of the reduced model."""
        return [f.name for f in self.model.frames]

    def frame_id(self, name: str) -> int:
        """Pinocchio frame index of ``name``.

        Raises:
            UnknownFrameError: the frame does not exist (the message lists the valid body frames).
        """
        if not isinstance(name, str) or not self.model.existFrame(name):
            bodies = [f.name for f in self.model.frames if f.type == pin.FrameType.BODY]
            raise UnknownFrameError(f'unknown frame {name!r}; body frames of {self.full_model.name}: {bodies}')
        return self.model.getFrameId(name)

    def reduce_geometry(self, geometry: pin.GeometryModel) -> pin.GeometryModel:
        """``geometry``, a geometry model of :attr:`full_model` (the URDF's shapes), on
        :attr:`model`: each shape of a locked link fixed to the joint that carries it, at the
        held positions (``pin.buildReducedModel``), so that :meth:`update`'s pass places it."""
        _, reduced = pin.buildReducedModel(self.full_model, geometry, self._locked, self._held_q)
        return reduced

    # ------------------------------------------------------------------ update
    @property
    def state(self) -> np.ndarray | None:
        """``q = (x, y, θ, q_m)`` of the last :meth:`update` (a copy); None before the first."""
        return None if self._q_flat is None else self._q_flat.copy()

    def configuration(self, base_pose: ArrayLike, q_arm: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Pinocchio configuration vector for a base pose (x, y, θ) and arm joint values (n,).

        Returns:
            (q_pin, flat): pinocchio's configuration and the (3 + n,) vector (x, y, θ, q_m).
        """
        flat = np.empty(self.nv)
        flat[:N_BASE] = _checked(base_pose, N_BASE, 'base_pose')
        flat[N_BASE:] = _checked(q_arm, self.n_arm, 'q_arm')
        q = self._q.copy()
        q[:N_BASE] = flat[:N_BASE]
        if self._plain_q.size:
            q[self._plain_q] = flat[self._plain_v]
        if self._cont_q.size:
            q[self._cont_q], q[self._cont_q + 1] = continuous_to_q(flat[self._cont_v])
        return q, flat

    def update(
        self,
        base_pose: ArrayLike,
        q_arm: ArrayLike,
        base_rate: ArrayLike | None = None,
        dq_arm: ArrayLike | None = None,
    ) -> None:
        """Run forward kinematics and the Jacobians for one state: every joint's placement and
        Jacobian (``data.oMi``, ``data.J``, world frame), which the collision model built on this
        model reads as they are (:class:`~wmm_control.kinematics.collision.CollisionModel`).

        Args:
            base_pose: (x, y, θ) of the base in the world [m, m, rad]. Shape (3,).
            q_arm: arm joint values [rad or m]. Shape (n,).
            base_rate: (ẋ, ẏ, θ̇) world-frame base rates [m/s, m/s, rad/s]. Shape (3,).
                Needed, with ``dq_arm``, for :meth:`jdot_qdot`.
            dq_arm: arm joint rates [rad/s or m/s]. Shape (n,).

        Raises:
            ShapeError, NonFiniteError: on a wrong size or a NaN/inf entry.
        """
        q, flat = self.configuration(base_pose, q_arm)
        if (base_rate is None) != (dq_arm is None):
            raise WmmError('give both base_rate and dq_arm, or neither')
        if base_rate is not None:
            v = np.empty(self.nv)
            v[:N_BASE] = _checked(base_rate, N_BASE, 'base_rate')
            v[N_BASE:] = _checked(dq_arm, self.n_arm, 'dq_arm')
            pin.forwardKinematics(self.model, self.data, q, v, np.zeros(self.nv))
            pin.computeJointJacobians(self.model, self.data)
            self._v = v
        else:
            pin.computeJointJacobians(self.model, self.data, q)
            self._v = None
        self._oMee = pin.updateFramePlacement(self.model, self.data, self._ee_id)
        self._oMb = pin.updateFramePlacement(self.model, self.data, self._base_id)
        self._jac = pin.getFrameJacobian(self.model, self.data, self._ee_id, _LWA)
        self._q = q
        self._q_flat = flat
        self._bMee = None
        self._rpy_base = None
        self._valid = True
        self.revision += 1

    def _require(self):
        if not self._valid:
            raise WmmError('call update(base_pose, q_arm) first')

    # ------------------------------------------------------------------ poses
    def frame_placement_world(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """World pose of any frame: (position (3,), rotation (3, 3))."""
        self._require()
        m = pin.updateFramePlacement(self.model, self.data, self.frame_id(name))
        return m.translation.copy(), m.rotation.copy()

    def ee_placement_world(self) -> tuple[np.ndarray, np.ndarray]:
        """End-effector position (3,) [m] and rotation (3, 3) in the world frame."""
        self._require()
        return self._oMee.translation.copy(), self._oMee.rotation.copy()

    def _base_ee(self):
        if self._bMee is None:
            self._bMee = self._oMb.actInv(self._oMee)
            self._rpy_base = rpy_from_matrix(self._bMee.rotation)
        return self._bMee

    def ee_placement_base(self) -> tuple[np.ndarray, np.ndarray]:
        """End-effector position (3,) [m] and rotation (3, 3) in the base frame."""
        self._require()
        m = self._base_ee()
        return m.translation.copy(), m.rotation.copy()

    def arm_points_world(self) -> np.ndarray:
        """World positions of the arm joint origins and of the end effector [m]. Shape (8, 3).

        With the base origin, they outline the robot's footprint (Sorour Fig 5).
        """
        self._require()
        pts = [self.data.oMi[j].translation for j in self._arm_joint_ids]
        pts.append(self._oMee.translation)
        return np.array(pts)

    def ee_pose_world(self) -> np.ndarray:
        """World end-effector pose [x, y, z, roll, pitch, yaw]. Shape (6,)."""
        pos, rot = self.ee_placement_world()
        return np.concatenate((pos, rpy_from_matrix(rot)))

    def ee_pose_base(self) -> np.ndarray:
        """Base-frame end-effector pose [x, y, z, roll, pitch, yaw]. Shape (6,)."""
        self._require()
        out = np.empty(6)
        out[:3] = self._base_ee().translation
        out[3:] = self._rpy_base
        return out

    # ------------------------------------------------------------------ Jacobians
    def jacobian_world(self) -> np.ndarray:
        """World-frame Jacobian over (x_b, y_b, θ_b, q_m) at the end-effector point (Xing eq 2).

        Rows: linear then angular velocity, world axes. Shape (6, 3 + n).
        """
        self._require()
        return self._jac.copy()

    def arm_jacobian_base(self) -> np.ndarray:
        """Arm geometric Jacobian J_a in the base frame (Sorour eq 1). Shape (6, 7)."""
        self._require()
        rt = self._oMb.rotation.T
        out = np.empty((6, self.n_arm))
        np.dot(rt, self._jac[:3, N_BASE:], out=out[:3])
        np.dot(rt, self._jac[3:, N_BASE:], out=out[3:])
        return out

    def h_matrix(self) -> np.ndarray:
        """Sorour eq (4): maps the base twist [ẋ ẏ 0 0 0 ω] (base frame) to the EE velocity. Shape (6, 6)."""
        self._require()
        pos = self._base_ee().translation
        h = np.zeros((6, 6))
        h[0, 0] = h[1, 1] = h[5, 5] = 1.0
        h[0, 5] = -pos[1]
        h[1, 5] = pos[0]
        return h

    def jmm(self, damping: float = 1e-6) -> np.ndarray:
        """Sorour eq (7): ``J_mm = M_RPY [H J_b, J_a]`` with J_b = I₆. Shape (6, 6 + n).

        ``M_RPY = blockdiag(I₃, Ω⁻¹)`` at the RPY angles of the base-frame EE
        orientation, Ω⁻¹ damped by ``damping`` (see :func:`rpy_rate_map`).
        """
        self._require()
        self._base_ee()
        out = np.empty((6, 6 + self.n_arm))
        out[:, :6] = self.h_matrix()
        out[:, 6:] = self.arm_jacobian_base()
        # M_RPY only changes the angular rows: rows 3..5 ← Ω⁻¹ rows 3..5.
        out[3:] = rpy_rate_map(self._rpy_base, damping)[3:, 3:] @ out[3:]  # type: ignore[arg-type]  # set by _base_ee()
        return out

    def jdot_qdot(self) -> np.ndarray:
        """``J̇ q̇`` at the end-effector point, world axes (Xing eq 4). Shape (6,).

        The classical acceleration of the end effector for ``q̈ = 0``.

        Raises:
            WmmError: :meth:`update` was called without rates.
        """
        self._require()
        if self._v is None:
            raise WmmError('jdot_qdot needs update(..., base_rate=..., dq_arm=...)')
        acc = pin.getFrameClassicalAcceleration(self.model, self.data, self._ee_id, _LWA)
        return np.concatenate((acc.linear, acc.angular))

    def arm_jacobian_world(self, rows: str = 'position') -> np.ndarray:
        """Arm part J_m of the world Jacobian: 'position' (3, 7) or 'full' (6, 7) rows."""
        picked = arm_rows(rows)  # the argument first: its error holds whatever the state
        self._require()
        return self._jac[picked, N_BASE:].copy()


def _checked(value, size, name):
    """Fast path of :func:`as_finite_vector` for the per-cycle update."""
    arr = np.asarray(value, dtype=float)
    if arr.shape != (size,) or not np.isfinite(arr).all():
        return as_finite_vector(arr, size, name)  # raises the detailed error
    return arr


def arm_rows(rows: str) -> slice:
    """The slice of :data:`ARM_ROWS` named ``rows``.

    Raises:
        WmmError: an unknown name.
    """
    try:
        return ARM_ROWS[rows]
    except KeyError as exc:
        raise WmmError(f"rows must be 'position' or 'full', got {rows!r}") from exc
