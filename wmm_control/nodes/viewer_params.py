"""The parameters of ``wmm_viewer`` (:mod:`wmm_control.nodes.viewer`), with their defaults in
``config/wmm_viewer.yaml``, and the check of their values together."""

from types import SimpleNamespace

from wmm_control.nodes.obstacle_topic import obstacle_params
from wmm_control.nodes.parameters import Param, robot_param

__all__ = ['PARAMS', 'check']

PARAMS = (
    robot_param('The robot drawn (its URDF, base link, end-effector frame and floor height).'),
    Param(
        'host',
        'Address the HTTP server listens on: 127.0.0.1 (this machine only), or another one, e.g. 0.0.0.0 '
        '(every interface), where the page shows the robot but commands nothing unless allow_remote_commands.',
        read_only=True,
    ),
    Param(
        'allow_remote_commands',
        'On a host other than this machine alone, let the page command the robot (the goal handle, Hold here): '
        'anyone who can reach the port can then send it goals.',
        read_only=True,
    ),
    Param(
        'port', 'HTTP port of the viewer; when it is taken, the next free one (logged).', lo=1, hi=65535, read_only=True
    ),
    Param('world_frame', 'Frame of /goal_pose, /ee_reference and /obstacles.', read_only=True),
    *obstacle_params(),
    Param(
        'update_period',
        'Steady time [s] between two scene updates sent to the browser.',
        lo=0.01,
        hi=1.0,
        read_only=True,
    ),
    Param(
        'drag_publish_period',
        'While the goal handle is dragged, /goal_pose goes out at most this often [s]; once more at release.',
        lo=0.05,
        hi=60.0,
    ),
    Param(
        'ground_truth_timeout',
        'The base pose comes from /ground_truth/odom while its last message is younger '
        'than this [s] (steady clock, at receipt), else from /odom.',
        lo=0.01,
        hi=60.0,
    ),
    Param('trail_length', 'Points kept on the end-effector and base paths.', lo=2, hi=1_000_000, read_only=True),
    Param('trail_step', 'Distance [m] between two points of a path.', lo=1e-4, hi=10.0, read_only=True),
)


def check(values: SimpleNamespace) -> str:
    """'' or why the parameter values cannot serve a page (an empty host)."""
    if not str(values.host).strip():
        return 'parameter host: empty; give an address, e.g. 127.0.0.1 or 0.0.0.0'
    return ''
