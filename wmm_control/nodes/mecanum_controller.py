"""``mecanum_controller`` and ``differential_controller``: the base controller of a Mecanum
base (robot B, Xing eq 16) or a differential-drive base as a node (one class, two executables;
each checks its robot's base family).

The node is :class:`~wmm_control.nodes.base_controller.BaseControllerNode` for a wheeled base
(:class:`~wmm_control.base.WheelBaseController`: :class:`~wmm_control.base.WheelController`); topics,
exchange and safety are described there. Its one command group is ``wheel``: the wheel rates
[rad/s] on ``/wheel_controller/commands``, order of the robot YAML's ``wheel_joints`` (Mecanum:
any N ≥ 3 wheels; differential left, right). A differential base's reference loses its vy (it
cannot move sideways): the feasible twist says what it follows, and the resolver's arm
compensation covers the rest. ``/diagnostics`` adds the velocity and acceleration scales, the
limited and dropped parts of the reference and the wheel rates. Geometry (R and the wheel
positions and roller angles, or the track), the wheel joints and every limit come from the robot description;
``config/mecanum_controller.yaml`` and ``config/differential_controller.yaml`` hold only the
node's tuning.
"""

import functools
from typing import Any

from wmm_control.nodes.base_controller_params import WHEEL_PARAMS as PARAMS
from wmm_control.nodes.base_controller import BaseControllerNode
from wmm_control.nodes.runner import run_node

__all__ = ['MecanumControllerNode', 'PARAMS', 'main', 'main_differential']


class MecanumControllerNode(BaseControllerNode):
    """The base controller node of a Mecanum or differential base.

    Args:
        family: the base family this executable drives (``mecanum`` or ``differential``); its
            node name is ``<family>_controller``.
    """

    def __init__(self, family: str = 'mecanum', **kwargs: Any) -> None:
        super().__init__(family, **kwargs)


def main(args: list[str] | None = None) -> int:
    return run_node(MecanumControllerNode, args)


def main_differential(args: list[str] | None = None) -> int:
    """``differential_controller``: the same node for a differential-drive base."""
    return run_node(functools.partial(MecanumControllerNode, family='differential'), args)


if __name__ == '__main__':
    raise SystemExit(main())
