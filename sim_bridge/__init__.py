"""Simulator bridge: a ROS-free PyBullet world (:class:`SimWorld`), its slip model and renderer.

The ROS node that wraps the world lives in ``sim_bridge/node.py`` (its parameters in
``node_params.py``, its messages in ``outputs.py``) and is not imported here, so this package
needs no rclpy; ``supervision.py`` holds the node's rules between steps, ROS-free.
"""

from sim_bridge.render import VIEWS, render_png, render_rgb
from sim_bridge.slip import SlipModel, SlipParams
from sim_bridge.world import BASE_MODES, CommandResult, SimWorld

__all__ = [
    'SimWorld',
    'CommandResult',
    'BASE_MODES',
    'SlipParams',
    'SlipModel',
    'render_png',
    'render_rgb',
    'VIEWS',
]
