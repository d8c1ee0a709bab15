"""The arm command's wait for the base's answer (Sorour eqs 14–15), ROS-free.

One exchange per control cycle: the cycle's base reference goes out, the base controller
answers that very reference with the twist it can follow (the feasible twist), and the arm
command goes out compensated for the difference (:meth:`Resolver.compensate
<wmm_control.resolvers.interface.Resolver.compensate>`). :class:`CompensationExchange` holds
the arm command of the cycle under way; an answer for another cycle is not its answer, and a
command whose answer does not come (a timeout, or the next cycle starting) goes out without
the compensation, counted.
"""

from typing import Any

from numpy.typing import ArrayLike

from wmm_control.resolvers.interface import Resolver, ResolverCommand

__all__ = ['CompensationExchange']


class CompensationExchange:
    """The arm command of one cycle, held until the feasible twist of its base reference comes.

    Args:
        resolver: the :class:`~wmm_control.resolvers.Resolver` that compensates.

    Attributes:
        dropped: commands that went out without their compensation.
    """

    def __init__(self, resolver: Resolver) -> None:
        self.resolver = resolver
        self.dropped = 0
        self._pending: tuple | None = None

    @property
    def pending(self) -> bool:
        """An arm command waits for its answer."""
        return self._pending is not None

    def hold(self, key, command, stamp) -> None:
        """Hold the arm ``command`` of the cycle ``key`` (its reference's stamp) until its answer."""
        self._pending = (key, command, stamp)

    def awaits(self, key) -> bool:
        """Whether an answer to the reference ``key`` is the one awaited."""
        return self._pending is not None and key == self._pending[0]

    def finish(self, feasible: ArrayLike | None = None) -> tuple[ResolverCommand, Any]:
        """(arm command, stamp) of the held cycle, compensated for the feasible twist (vx, vy, ω)
        when it is given, else as it is (counted in ``dropped``); nothing is held afterwards."""
        _, command, stamp = self._pending  # type: ignore[misc]  # called while a command is held
        self._pending = None
        if feasible is None:
            self.dropped += 1
            return command, stamp
        return self.resolver.compensate(command, feasible), stamp

    def clear(self) -> None:
        """Give up the held command (the robot is being stopped)."""
        self._pending = None
