"""Mobile-base kinematics and controllers: steerable (Sorour §IV), Mecanum (Xing eq 16) and
differential drive, and the one contract they all meet (:mod:`wmm_control.base.contract`)."""

from wmm_control.base.applied import unapplied_command
from wmm_control.base.differential import DifferentialKinematics
from wmm_control.base.icr import Icr, choose_route
from wmm_control.base.mecanum import MecanumKinematics
from wmm_control.base.wheel_controller import WheelController, WheelOutput, WheelParams, wheel_kinematics
from wmm_control.base.steerable_kinematics import SteerableGeometry
from wmm_control.base.swmr_controller import (
    IcrQp,
    OsqpIcrSolver,
    QpResult,
    SwmrController,
    SwmrOutput,
    SwmrParams,
)
from wmm_control.base.contract import (
    BaseCommand,
    BaseController,
    SteerableBaseController,
    WheelBaseController,
    make_base_controller,
)

__all__ = [
    'BaseCommand',
    'BaseController',
    'DifferentialKinematics',
    'Icr',
    'IcrQp',
    'WheelBaseController',
    'WheelController',
    'MecanumKinematics',
    'WheelOutput',
    'WheelParams',
    'OsqpIcrSolver',
    'QpResult',
    'SteerableBaseController',
    'SteerableGeometry',
    'SwmrController',
    'SwmrOutput',
    'SwmrParams',
    'choose_route',
    'make_base_controller',
    'unapplied_command',
    'wheel_kinematics',
]
