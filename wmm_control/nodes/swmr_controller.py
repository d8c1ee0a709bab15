"""``swmr_controller``: the steerable-base controller of Sorour §IV as a node.

The node is :class:`~wmm_control.nodes.base_controller.BaseControllerNode` for a steerable
base (:class:`~wmm_control.base.SteerableBaseController`: :class:`~wmm_control.base.SwmrController`);
topics, exchange and safety are described there. Its command groups are ``steer`` (β̇_ref,
order ``steer_joints``, on ``/steer_controller/commands``) and ``drive`` (φ̇_ref, order
``drive_joints``, on ``/drive_controller/commands``); each cycle closes on the measured steer
angles, and ``/base/feasible_twist`` is the twist the base executes over the coming period
(compatible with the next ICR, corrected for the steering during the period). ``/diagnostics``
adds the ICR, route, active constraints and solve time. A stale reference brakes the base and
holds the steer angles; a QP failure holds the steering and ramps the drive down. Its own
parameters are the gains ``kp`` and ``icr_gain`` (``config/swmr_controller.yaml``, Sorour
Table I).
"""

from typing import Any

from wmm_control.nodes.base_controller_params import STEERABLE_PARAMS as PARAMS
from wmm_control.nodes.base_controller import BaseControllerNode
from wmm_control.nodes.runner import run_node

__all__ = ['PARAMS', 'SwmrControllerNode', 'main']


class SwmrControllerNode(BaseControllerNode):
    """The base controller node of a steerable base (node name ``swmr_controller``)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('steerable', **kwargs)


def main(args: list[str] | None = None) -> int:
    return run_node(SwmrControllerNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
