"""Mobile-base kinematics and controllers: steerable (Sorour §IV) and Mecanum (Xing eq 16)."""

from wmm_control.base.applied import unapplied_command
from wmm_control.base.icr import Icr, choose_route
from wmm_control.base.mecanum import MecanumKinematics
from wmm_control.base.mecanum_controller import MecanumController, MecanumOutput, MecanumParams
from wmm_control.base.steerable_kinematics import SteerableGeometry
from wmm_control.base.swmr_controller import (
    IcrQp,
    OsqpIcrSolver,
    QpResult,
    SwmrController,
    SwmrOutput,
    SwmrParams,
)

__all__ = [
    'Icr',
    'IcrQp',
    'MecanumController',
    'MecanumKinematics',
    'MecanumOutput',
    'MecanumParams',
    'OsqpIcrSolver',
    'QpResult',
    'SteerableGeometry',
    'SwmrController',
    'SwmrOutput',
    'SwmrParams',
    'choose_route',
    'unapplied_command',
]
