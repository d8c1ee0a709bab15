"""Whether an actuator applied the last command: what a base controller checks before it goes on
from its own last command (ROS-free; the base controller nodes call it on each joint state)."""

import numpy as np
from numpy.typing import ArrayLike

__all__ = ['unapplied_command']


def unapplied_command(measured: ArrayLike | None, commanded: ArrayLike | None, tolerance: float) -> str:
    """'' when a joint state's rates are the last command's, else why not.

    A joint state reports the rates the actuator applied over the period it closes: those of
    the last command, unless that command was not applied as sent. It may have been lost or
    late, superseded (a controller that answers queued joint states back to back sends several
    commands within one period, and the actuator applies only the last), or zeroed by the
    actuator's command timeout. A controller that went on from its own last command would
    then change the applied rates by as many periods of acceleration as it answered meanwhile.

    Args:
        measured: the rates of the joint state [rad/s], or None (the message has none).
        commanded: the rates last commanded [rad/s], or None (none yet), same order.
        tolerance: largest difference [rad/s] still taken as applied; 0 turns the check off.
    """
    if tolerance <= 0.0 or measured is None or commanded is None:
        return ''
    worst = float(np.max(np.abs(np.asarray(measured, dtype=float) - np.asarray(commanded, dtype=float))))
    if worst <= tolerance:
        return ''
    return (
        f'the rates measured differ from the last command by up to {worst:.3g} rad/s (more than '
        f'{tolerance:g}): it was not applied as sent (lost, late, superseded, or zeroed by the '
        'actuator\'s command timeout)'
    )
