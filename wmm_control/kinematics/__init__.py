"""ROS-free kinematics: the pinocchio model and orientation utilities."""

from wmm_control.kinematics.model import KinematicModel, build_pinocchio_model, N_BASE
from wmm_control.kinematics.orientation import (
    matrix_from_rpy,
    omega_rpy,
    pose_error_log,
    pose_error_rpy,
    rpy_from_matrix,
    rpy_rate_map,
    wrap_angle,
)

__all__ = [
    'KinematicModel',
    'build_pinocchio_model',
    'N_BASE',
    'matrix_from_rpy',
    'omega_rpy',
    'pose_error_log',
    'pose_error_rpy',
    'rpy_from_matrix',
    'rpy_rate_map',
    'wrap_angle',
]
