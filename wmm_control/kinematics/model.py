"""Kinematic model of a wheeled mobile manipulator, on pinocchio.

The generalized coordinates are ``q = (x_b, y_b, θ_b, q_m)``: the planar base pose in
the world frame followed by the 7 arm joints (Xing eq 2). The wheel-side joints of the
URDF (steer, drive, Mecanum wheels) are locked out of this model: they do not move the
end effector.

Quantities (Sorour §II, Xing §2 and appendices A–B):

* end-effector pose in the base and world frames;
* ``J_a``: arm geometric Jacobian in the base frame (Sorour eq 1). Shape (6, 7);
* ``H``: the base-to-end-effector velocity map of Sorour eq (4). Shape (6, 6);
* ``J_mm = M_RPY [H J_b, J_a]`` (eq 7), with ``M_RPY = blockdiag(I, Ω⁻¹)``, the RPY rates
  of the base-frame end-effector orientation. Shape (6, 13);
* ``J``: world-frame Jacobian over ``q`` (Xing eq 2) and ``J̇q̇`` (eq 4). Shapes (6, 10), (6,);
* manipulability ``det(J_m J_mᵀ)``, its gradient and Hessian over ``q_m``, and
  ``σ_min(J_m)``; ``J_m`` is the arm Jacobian (position rows, or all six).

Usage::

    model = KinematicModel('steerable')
    model.update(base_pose, q_arm)           # one FK + Jacobian pass
    pos, rot = model.ee_placement_world()
    ja = model.arm_jacobian_base()
"""

import numpy as np
import pinocchio as pin

from wmm_control.checks import as_finite_vector
from wmm_control.errors import ConfigError, UnknownFrameError, WmmError
from wmm_control.kinematics.orientation import rpy_from_matrix, rpy_rate_map
from wmm_control.robot_config import RobotConfig, load_robot

__all__ = ['KinematicModel', 'build_pinocchio_model', 'N_BASE']

N_BASE = 3
_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
_ROWS = {'position': slice(0, 3), 'full': slice(0, 6)}


def build_pinocchio_model(urdf_path):
    """Load a URDF with a planar (x, y, θ) root joint made of PX, PY and RZ.

    The composite root keeps ``q`` and ``v`` equal to (x, y, θ) and their world-frame
    rates, unlike pinocchio's planar joint (cos/sin in q, body-frame velocity).
    """
    root = pin.JointModelComposite()
    root.addJoint(pin.JointModelPX())
    root.addJoint(pin.JointModelPY())
    root.addJoint(pin.JointModelRZ())
    try:
        return pin.buildModelFromUrdf(str(urdf_path), root)
    except (RuntimeError, ValueError) as exc:
        raise ConfigError(f'pinocchio could not load {urdf_path}: {exc}') from exc


def angles_to_pin_q(model, joint_angles):
    """Pinocchio configuration from one number per joint velocity (angles for continuous joints).

    Continuous joints (nq = 2) take (cos, sin) of the angle; others take the value itself.

    Args:
        joint_angles: one entry per velocity index. Shape (model.nv,).
    """
    q = pin.neutral(model)
    for joint in model.joints[1:]:
        iq, iv = joint.idx_q, joint.idx_v
        if joint.nq == 2 and joint.nv == 1:
            q[iq] = np.cos(joint_angles[iv])
            q[iq + 1] = np.sin(joint_angles[iv])
        else:
            q[iq:iq + joint.nq] = joint_angles[iv:iv + joint.nv]
    return q


class KinematicModel:
    """Kinematics of one robot: base pose + 7 arm joints → end effector.

    Args:
        robot: robot name (``'steerable'``/``'A'``, ``'mecanum'``/``'B'``), YAML path, or
            a loaded :class:`RobotConfig`.
        ee_frame: end-effector frame name; defaults to the robot's ``ee_frame``.

    Raises:
        ConfigError: the robot files are invalid or the arm joints are not in the URDF.
        UnknownFrameError: ``ee_frame`` is not a frame of the URDF.
    """

    def __init__(self, robot='steerable', ee_frame=None):
        self.config = robot if isinstance(robot, RobotConfig) else load_robot(robot)
        self.full_model = build_pinocchio_model(self.config.urdf_path)
        arm_names = self.config.arm.joints
        missing = [n for n in arm_names if not self.full_model.existJointName(n)]
        if missing:
            raise ConfigError(f'arm joints {missing} are not in {self.config.urdf_path.name}')
        locked = [self.full_model.getJointId(n) for n in self.full_model.names[1:]
                  if n not in arm_names and n != 'root_joint']
        self.model = pin.buildReducedModel(self.full_model, locked, pin.neutral(self.full_model))
        self.data = self.model.createData()
        names = list(self.model.names[2:])
        if names != list(arm_names):
            raise ConfigError(f'arm joints must form one chain in the order {list(arm_names)}, '
                              f'the URDF gives {names}')
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
        self.ee_frame = ee_frame or self.config.ee_frame
        self._ee_id = self.frame_id(self.ee_frame)
        self._base_id = self.frame_id(self.config.base_link)
        self._q = pin.neutral(self.model)
        self._q_flat = None
        self._v = None
        self._valid = False
        self._jac = np.zeros((6, self.nv))

    # ------------------------------------------------------------------ frames
    @property
    def frame_names(self):
        """Names of every frame of the reduced model."""
        return [f.name for f in self.model.frames]

    def frame_id(self, name):
        """Pinocchio frame index of ``name``.

        Raises:
            UnknownFrameError: the frame does not exist (the message lists the valid body frames).
        """
        if not isinstance(name, str) or not self.model.existFrame(name):
            bodies = [f.name for f in self.model.frames if f.type == pin.FrameType.BODY]
            raise UnknownFrameError(f'unknown frame {name!r}; body frames of {self.config.name}: {bodies}')
        return self.model.getFrameId(name)

    # ------------------------------------------------------------------ update
    def configuration(self, base_pose, q_arm):
        """Pinocchio configuration vector for a base pose (x, y, θ) and arm angles (7,).

        Returns:
            (q_pin, flat): pinocchio's configuration and the (10,) vector (x, y, θ, q_m).
        """
        flat = np.empty(self.nv)
        flat[:N_BASE] = _checked(base_pose, N_BASE, 'base_pose')
        flat[N_BASE:] = _checked(q_arm, self.n_arm, 'q_arm')
        q = self._q.copy()
        q[:N_BASE] = flat[:N_BASE]
        if self._plain_q.size:
            q[self._plain_q] = flat[self._plain_v]
        if self._cont_q.size:
            angles = flat[self._cont_v]
            q[self._cont_q] = np.cos(angles)
            q[self._cont_q + 1] = np.sin(angles)
        return q, flat

    def update(self, base_pose, q_arm, base_rate=None, dq_arm=None):
        """Run forward kinematics and the Jacobians for one state.

        Args:
            base_pose: (x, y, θ) of the base in the world [m, m, rad]. Shape (3,).
            q_arm: arm joint angles [rad]. Shape (7,).
            base_rate: (ẋ, ẏ, θ̇) world-frame base rates [m/s, m/s, rad/s]. Shape (3,).
                Needed, with ``dq_arm``, for :meth:`jdot_qdot`.
            dq_arm: arm joint rates [rad/s]. Shape (7,).

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

    def _require(self):
        if not self._valid:
            raise WmmError('call update(base_pose, q_arm) first')

    # ------------------------------------------------------------------ poses
    def frame_placement_world(self, name):
        """World pose of any frame: (position (3,), rotation (3, 3))."""
        self._require()
        m = pin.updateFramePlacement(self.model, self.data, self.frame_id(name))
        return m.translation.copy(), m.rotation.copy()

    def ee_placement_world(self):
        """End-effector position (3,) [m] and rotation (3, 3) in the world frame."""
        self._require()
        return self._oMee.translation.copy(), self._oMee.rotation.copy()

    def _base_ee(self):
        if self._bMee is None:
            self._bMee = self._oMb.actInv(self._oMee)
            self._rpy_base = rpy_from_matrix(self._bMee.rotation)
        return self._bMee

    def ee_placement_base(self):
        """End-effector position (3,) [m] and rotation (3, 3) in the base frame."""
        self._require()
        m = self._base_ee()
        return m.translation.copy(), m.rotation.copy()

    def arm_points_world(self):
        """World positions of the arm joint origins and of the end effector [m]. Shape (8, 3).

        With the base origin, they outline the robot's footprint (Sorour Fig 5).
        """
        self._require()
        pts = [self.data.oMi[j].translation for j in self._arm_joint_ids]
        pts.append(self._oMee.translation)
        return np.array(pts)

    def ee_pose_world(self):
        """World end-effector pose [x, y, z, roll, pitch, yaw]. Shape (6,)."""
        pos, rot = self.ee_placement_world()
        return np.concatenate((pos, rpy_from_matrix(rot)))

    def ee_pose_base(self):
        """Base-frame end-effector pose [x, y, z, roll, pitch, yaw]. Shape (6,)."""
        self._require()
        out = np.empty(6)
        out[:3] = self._base_ee().translation
        out[3:] = self._rpy_base
        return out

    # ------------------------------------------------------------------ Jacobians
    def jacobian_world(self):
        """World-frame Jacobian over (x_b, y_b, θ_b, q_m) at the end-effector point (Xing eq 2).

        Rows: linear then angular velocity, world axes. Shape (6, 10).
        """
        self._require()
        return self._jac.copy()

    def arm_jacobian_base(self):
        """Arm geometric Jacobian J_a in the base frame (Sorour eq 1). Shape (6, 7)."""
        self._require()
        rt = self._oMb.rotation.T
        out = np.empty((6, self.n_arm))
        np.dot(rt, self._jac[:3, N_BASE:], out=out[:3])
        np.dot(rt, self._jac[3:, N_BASE:], out=out[3:])
        return out

    def h_matrix(self):
        """Sorour eq (4): maps the base twist [ẋ ẏ 0 0 0 ω] (base frame) to the EE velocity. Shape (6, 6)."""
        self._require()
        pos = self._base_ee().translation
        h = np.zeros((6, 6))
        h[0, 0] = h[1, 1] = h[5, 5] = 1.0
        h[0, 5] = -pos[1]
        h[1, 5] = pos[0]
        return h

    def jmm(self, damping=1e-6):
        """Sorour eq (7): ``J_mm = M_RPY [H J_b, J_a]`` with J_b = I₆. Shape (6, 13).

        ``M_RPY = blockdiag(I₃, Ω⁻¹)`` at the RPY angles of the base-frame EE
        orientation, Ω⁻¹ damped by ``damping`` (see :func:`rpy_rate_map`).
        """
        self._require()
        self._base_ee()
        out = np.empty((6, 6 + self.n_arm))
        out[:, :6] = self.h_matrix()
        out[:, 6:] = self.arm_jacobian_base()
        # M_RPY only changes the angular rows: rows 3..5 ← Ω⁻¹ rows 3..5.
        out[3:] = rpy_rate_map(self._rpy_base, damping)[3:, 3:] @ out[3:]
        return out

    def jdot_qdot(self):
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

    # ------------------------------------------------------------------ manipulability
    def arm_jacobian_world(self, rows='position'):
        """Arm part J_m of the world Jacobian: 'position' (3, 7) or 'full' (6, 7) rows."""
        self._require()
        return self._jac[_rows(rows), N_BASE:].copy()

    def sigma_min(self, rows='position'):
        """Smallest singular value of J_m (a distance-to-singularity measure)."""
        return float(np.linalg.svd(self.arm_jacobian_world(rows), compute_uv=False)[-1])

    def manipulability(self, rows='position'):
        """``det(J_m J_mᵀ)`` (Xing eq 10; Yoshikawa's measure squared)."""
        jm = self.arm_jacobian_world(rows)
        return float(np.linalg.det(jm @ jm.T))

    def _arm_geometry(self):
        """Joint axes Z (7, 3), lever arms r_i = p_e − p_i (7, 3) in world axes."""
        z = self._jac[3:, N_BASE:].T
        pe = self._oMee.translation
        p = np.array([self.data.oMi[j].translation for j in self._arm_joint_ids])
        return z, pe - p

    def _jacobian_derivatives(self, second):
        """∂J_m/∂q_k (7, 6, 7) and optionally ∂²J_m/∂q_l∂q_k (7, 7, 6, 7), world axes.

        Revolute serial chain: ``J_i = [z_i × r_i; z_i]``, ``∂z_i/∂q_k = [k<i] z_k × z_i``,
        ``∂r_i/∂q_k = z_k × r_max(i,k)``; the second derivatives follow by the same rules.
        Index order: ``dj[k, :, i] = ∂J_i/∂q_k``, ``ddj[l, k, :, i] = ∂²J_i/∂q_l∂q_k``.
        """
        z, r = self._arm_geometry()
        n = self.n_arm
        idx = np.arange(n)
        lower = (idx[:, None] < idx[None, :]).astype(float)        # [k < i]
        mx = np.maximum.outer(idx, idx)                              # max(i, k)
        zk = z[:, None, :]
        dz = np.cross(zk, z[None, :, :]) * lower[:, :, None]        # (k, i, 3)
        dr = np.cross(zk, r[mx])                                     # (k, i, 3)
        da = np.cross(dz, r[None, :, :]) + np.cross(z[None, :, :], dr)
        dj = np.concatenate((da, dz), axis=2).transpose(0, 2, 1)     # (k, 6, i)
        if not second:
            return dj, None
        zl = z[:, None, None, :]
        zk3 = z[None, :, None, :]
        zi3 = z[None, None, :, :]
        lk = lower[:, :, None, None]                                 # [l < k]
        ki = lower[None, :, :, None]                                 # [k < i]
        li = lower[:, None, :, None]                                 # [l < i]
        zlzk = np.cross(zl, zk3)                                     # (l, k, 1, 3)
        dz2 = ki * (lk * np.cross(zlzk, zi3) + li * np.cross(zk3, np.cross(zl, zi3)))
        m_ki = mx                                                    # (k, i)
        r_m = r[m_ki][None, :, :, :]                                 # (1, k, i, 3)
        m3 = np.maximum(m_ki[None, :, :], idx[:, None, None])        # max(m, l)
        dr2 = lk * np.cross(zlzk, r_m) + np.cross(zk3, np.cross(zl, r[m3]))
        ri3 = r[None, None, :, :]
        da2 = (np.cross(dz2, ri3) + np.cross(dz[None, :, :, :], dr[:, None, :, :])
               + np.cross(dz[:, None, :, :], dr[None, :, :, :]) + np.cross(zi3, dr2))
        ddj = np.concatenate((da2, dz2), axis=3).transpose(0, 1, 3, 2)  # (l, k, 6, i)
        return dj, ddj

    def manipulability_gradient(self, rows='position'):
        """∂H/∂q_m of ``H = det(J_m J_mᵀ)`` (Xing appendix A). Shape (7,).

        ``∂H/∂q_k = H tr(M⁻¹ ∂M/∂q_k)`` with ``M = J_m J_mᵀ``.
        """
        grad, _ = self._manipulability_derivatives(rows, second=False)
        return grad

    def manipulability_hessian(self, rows='position'):
        """∂²H/∂q_m² (Xing appendix B). Shape (7, 7)."""
        _, hess = self._manipulability_derivatives(rows, second=True)
        return hess

    def _manipulability_derivatives(self, rows, second):
        sl = _rows(rows)
        jm = self._jac[sl, N_BASE:]
        dj, ddj = self._jacobian_derivatives(second)
        dj = dj[:, sl, :]
        m = jm @ jm.T
        h = float(np.linalg.det(m))
        minv = np.linalg.inv(m)
        djt = dj @ jm.T                                   # (k, r, r): ∂J_k Jᵀ
        dm = djt + djt.transpose(0, 2, 1)                 # ∂M/∂q_k
        t = np.einsum('ab,kba->k', minv, dm)              # tr(M⁻¹ ∂M_k)
        grad = h * t
        if not second:
            return grad, None
        ddj = ddj[:, :, sl, :]
        a = np.einsum('lab,kbc->lkac', dj, dj.transpose(0, 2, 1))   # ∂J_l ∂J_kᵀ
        b = ddj @ jm.T                                               # ∂²J_lk Jᵀ
        ddm = b + b.transpose(0, 1, 3, 2) + a + a.transpose(0, 1, 3, 2)
        mdm = minv[None] @ dm                                        # M⁻¹ ∂M_k
        cross = np.einsum('lab,kba->lk', mdm, mdm)                   # tr(M⁻¹∂M_l M⁻¹∂M_k)
        tr2 = np.einsum('ab,lkba->lk', minv, ddm)
        hess = np.outer(grad, t) + h * (tr2 - cross)
        return grad, 0.5 * (hess + hess.T)


def _checked(value, size, name):
    """Fast path of :func:`as_finite_vector` for the per-cycle update."""
    arr = np.asarray(value, dtype=float)
    if arr.shape != (size,) or not np.isfinite(arr).all():
        return as_finite_vector(arr, size, name)   # raises the detailed error
    return arr


def _rows(rows):
    try:
        return _ROWS[rows]
    except KeyError as exc:
        raise WmmError(f"rows must be 'position' or 'full', got {rows!r}") from exc
