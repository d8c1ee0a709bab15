"""Whether a goal is reached, or stalled: what ``redundancy_resolver`` reports on /diagnostics.

:class:`GoalProgress` follows a resolver's :class:`~wmm_control.resolvers.ResolverDiagnostics`
cycle by cycle. A goal is *reached* while both errors are within the tolerance. It is
*stalled* when it is not reached and has made no progress for ``stall_time``: progress is the
position error improving on its best value by ``min_progress``, or the orientation error
doing so while the position error stays within ``min_progress`` of its best (an end effector
that drifts away while it turns makes none). Then the method cannot take the end effector
further (a goal
out of reach, a joint held at its limit, a task-sharing split that leaves the arm alone with
a goal it cannot reach). The node and the randomized closed-loop runs share it.
"""

import math

__all__ = ['GoalProgress']


class GoalProgress:
    """Reached / stalled bookkeeping of one goal, in control cycles.

    Args:
        tolerance: (position [m], orientation [rad]) under which the goal is reached.
        stall_time: time without progress after which an unreached goal is stalled [s].
        period: control period [s].
        min_progress: (position [m], orientation [rad]) improvement that counts as progress.
    """

    def __init__(self, tolerance, stall_time, period, min_progress=(1e-3, 1e-3)):
        self.tolerance = tuple(float(v) for v in tolerance)
        self.stall_time = float(stall_time)
        self.period = float(period)
        self.min_progress = tuple(float(v) for v in min_progress)
        self.start()

    def start(self):
        """A new goal: no cycle seen, no progress yet."""
        self.cycles = 0
        self._best = (math.inf, math.inf)
        self._last_progress = 0
        self.reached = False

    def update(self, diagnostics):
        """Account for one cycle's diagnostics (``position_error``, ``orientation_error``)."""
        self.cycles += 1
        pos, ori = diagnostics.position_error, diagnostics.orientation_error
        self.reached = pos <= self.tolerance[0] and ori <= self.tolerance[1]
        best_pos, best_ori = self._best
        better_pos = pos < best_pos - self.min_progress[0]
        better_ori = ori < best_ori - self.min_progress[1] and pos <= best_pos + self.min_progress[0]
        if better_pos or better_ori or self.reached:
            self._last_progress = self.cycles
        self._best = (pos if better_pos else best_pos, ori if better_ori else best_ori)

    @property
    def stalled(self):
        """True when the goal is not reached and has made no progress for ``stall_time``."""
        return not self.reached and (self.cycles - self._last_progress) * self.period > self.stall_time
