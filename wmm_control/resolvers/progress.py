"""Whether a goal is reached, or stalled: what ``redundancy_resolver`` reports on /diagnostics.

:class:`GoalProgress` follows a resolver's :class:`~wmm_control.resolvers.ResolverDiagnostics`
cycle by cycle. A goal is *reached* while both errors are within the tolerance. It is
*stalled* when it is not reached, was not reached within the last ``stall_time`` either, and
made no progress over the last ``stall_time``. Progress, over that window, is

1. the **best** position error of the goal so far falling by at least ``min_progress``
   (1 mm) and at least ``min_progress_ratio`` (10 %) of its value at the window's start; or
   the best orientation error doing so (1 mrad, 10 %), counted only over cycles whose
   position error stays within that much of its best (an end effector that drifts away
   while it turns makes none);
2. and, once the goal is two windows old, the **held** error doing so as well: the largest
   error within a ``stall_time`` window is what the end effector stayed within, and the held
   error is the smallest such value of the goal so far. An end effector that swings through
   a closer point and away again improves its best error, not its held one: an oscillation
   whose swings bring it no closer makes no progress.

**While the target still moves** (an acceleration-level method's set-point trajectory, which
the goal becomes, has not ended: ``reference_time_left`` of the diagnostics) and for a
``stall_time`` after, there is no stall: until then the end effector follows the trajectory,
not the goal, and a slow start or a tracking lag may take it away from the goal for a while.

**While a motion gathers pace** (from the goal's start until the first window whose gain is
not larger than the one before), a best error falling by ``min_progress`` and by more than
in the window before also counts: a trajectory that starts with zero velocity and
acceleration (the acceleration-level methods' set-point trajectory, a quintic) or a base
that accelerates slowly covers only a small part of a long way in its first seconds.

Judged relative to the error, the rule reports a goal that the end effector approaches so
slowly that it will not get there: with the defaults, one whose error shrinks by less than
10 % in 3 s, a time constant above 28 s where the pose controller's is 1/λ_p = 0.6 s. Such a
goal is held back by a limit (a joint resting on it, a base that accelerates too slowly), a
singularity's damping, a task-sharing split that leaves the arm alone with a goal it cannot
reach, or the method oscillates around it. A goal out of reach stalls the same way. The node
and the randomized closed-loop runs share this rule.
"""

import bisect
import math
from collections import deque
from collections.abc import Iterable

from wmm_control.resolvers.interface import ResolverDiagnostics

__all__ = ['GoalProgress']

#: At most this many samples of the errors are kept per ``stall_time`` (a coarser stride for
#: a long stall time at a short period; a window is then judged to within 1/256 of it).
_SAMPLES_PER_WINDOW = 256


class GoalProgress:
    """Reached / stalled bookkeeping of one goal, in control cycles.

    Args:
        tolerance: (position [m], orientation [rad]) under which the goal is reached.
        stall_time: the window over which progress is judged [s].
        period: control period [s].
        min_progress: (position [m], orientation [rad]) improvement that counts as progress
            at the least.
        min_progress_ratio: fraction of an error at a window's start by which it must fall
            within ``stall_time`` to count as progress [-].
    """

    def __init__(
        self,
        tolerance: Iterable[float],
        stall_time: float,
        period: float,
        min_progress: Iterable[float] = (1e-3, 1e-3),
        min_progress_ratio: float = 0.1,
    ) -> None:
        self.tolerance = tuple(float(v) for v in tolerance)
        self.period = float(period)
        self.min_progress = tuple(float(v) for v in min_progress)
        self.min_progress_ratio = float(min_progress_ratio)
        self.stall_time = stall_time
        self.start()

    @property
    def stall_time(self) -> float:
        """The window over which progress is judged [s]."""
        return self._stall_time

    @stall_time.setter
    def stall_time(self, value: float) -> None:
        self._stall_time = float(value)
        self._window = max(1, int(round(self._stall_time / self.period)))
        self._stride = max(1, math.ceil(self._window / _SAMPLES_PER_WINDOW))

    def start(self) -> None:
        """A new goal: no cycle seen, no progress yet."""
        self.cycles = 0
        self.reached = False
        self.stalled = False
        self._best = [math.inf, math.inf]  # best (position, orientation) error of the goal
        self._held = [math.inf, math.inf]  # held (position, orientation) error of the goal
        self._block = [0.0, 0.0]  # largest errors of the stride under way
        # ...and of the strides before it, a window's worth: ``_kept`` strides, numbered from
        # ``_first``; for each error, a deque of (stride number, error) with the errors falling
        # from its head, the window's largest at the head (a sliding maximum)
        self._first, self._kept = 0, 0
        self._peaks: tuple[deque[tuple[int, float]], ...] = (deque(), deque())
        self._last_reached: int | None = None
        self._last_moving: int | None = None  # the last cycle whose target still moved
        self._gathering_pace = True
        self._cycles: deque[int] = deque()  # the cycles sampled, every stride...
        self._samples: deque[tuple[tuple[float, ...], tuple[float, ...]]] = deque()  # ...and (best, held) errors then

    def _needed(self, value, index):
        return max(self.min_progress[index], self.min_progress_ratio * value)

    def update(self, diagnostics: ResolverDiagnostics) -> None:
        """Account for one cycle's diagnostics (``position_error``, ``orientation_error``)."""
        self.cycles += 1
        pos, ori = diagnostics.position_error, diagnostics.orientation_error
        self.reached = pos <= self.tolerance[0] and ori <= self.tolerance[1]
        if self.reached:
            self._last_reached = self.cycles
        if getattr(diagnostics, 'reference_time_left', 0.0) > 0.0:
            self._last_moving = self.cycles
        best = self._best
        if pos < best[0]:
            best[0] = pos
        if ori < best[1] and pos <= best[0] + self._needed(best[0], 0):
            best[1] = ori
        self._block = [max(self._block[0], pos), max(self._block[1], ori)]
        window_max = self._window_max()
        if self.cycles >= self._window:
            self._held = [min(h, m) for h, m in zip(self._held, window_max)]
        if not self._cycles or self.cycles - self._cycles[-1] >= self._stride:
            self._cycles.append(self.cycles)
            self._samples.append((tuple(best), tuple(self._held)))
            number = self._first + self._kept
            for peaks, value in zip(self._peaks, self._block):
                while peaks and peaks[-1][1] <= value:
                    peaks.pop()
                peaks.append((number, value))
            self._kept += 1
            self._block = [0.0, 0.0]
        while len(self._cycles) > 1 and self._cycles[1] <= self.cycles - 2 * self._window:
            self._cycles.popleft()
            self._samples.popleft()
        while self._kept * self._stride > self._window:
            self._first += 1
            self._kept -= 1
        for peaks in self._peaks:
            while peaks and peaks[0][0] < self._first:
                peaks.popleft()
        self.stalled = not self.reached and not self._progress(window_max)

    def _window_max(self):
        """The largest (position, orientation) errors of about the last ``stall_time``."""
        (pos, ori), (peak_pos, peak_ori) = self._block, self._peaks
        return max(pos, peak_pos[0][1] if peak_pos else 0.0), max(ori, peak_ori[0][1] if peak_ori else 0.0)

    def _at(self, cycle):
        """(best, held) errors at the latest sample not after ``cycle`` (the oldest sample kept
        when none is that old: before the goal's first cycle nothing was gained)."""
        return self._samples[max(0, bisect.bisect_right(self._cycles, cycle) - 1)]

    def _gained(self, before, now, held_position=None):
        """Whether (position, orientation) errors fell from ``before`` to ``now`` by the margin;
        the orientation counts only while ``held_position`` (when given) keeps near its best."""
        if before[0] - now[0] >= self._needed(before[0], 0):
            return True
        if held_position is not None and held_position > now[0] + self._needed(now[0], 0):
            return False
        return math.isfinite(before[1]) and before[1] - now[1] >= self._needed(before[1], 1)

    def _progress(self, window_max):
        """Whether the goal made progress over the last ``stall_time`` (module docstring)."""
        window = self._window
        if self.cycles <= window:
            return True  # not a whole window yet
        if any(last is not None and self.cycles - last <= window for last in (self._last_reached, self._last_moving)):
            return True
        best0, held0 = self._at(self.cycles - window)
        if self._gained(best0, self._best) and (
            self.cycles < 2 * window or self._gained(held0, self._held, window_max[0])
        ):
            return True
        if self._gathering_pace:
            best1, _ = self._at(self.cycles - 2 * window)
            if any(
                best0[i] - self._best[i] >= self.min_progress[i] and best0[i] - self._best[i] > best1[i] - best0[i]
                for i in (0, 1)
                if math.isfinite(best1[i])
            ):
                return True
            self._gathering_pace = False
        return False
