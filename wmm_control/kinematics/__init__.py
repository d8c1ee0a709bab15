"""ROS-free kinematics: the pinocchio model (rotations and planar poses: :mod:`wmm_control.geometry`)."""

from wmm_control.kinematics.model import KinematicModel, pinocchio_model, N_BASE

__all__ = ['KinematicModel', 'pinocchio_model', 'N_BASE']
