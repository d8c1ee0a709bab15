"""Exceptions raised by the wmm_control core.

Every input check raises one of these, with a message that names the offending
shape, value or name, so that a node can log it and reject the input.
"""

__all__ = [
    'WmmError',
    'ConfigError',
    'ShapeError',
    'NonFiniteError',
    'UnknownFrameError',
]


class WmmError(Exception):
    """Base class of every error raised by wmm_control."""


class ConfigError(WmmError):
    """A robot description or parameter file is missing, malformed or inconsistent."""


class ShapeError(WmmError, ValueError):
    """An array argument has the wrong shape."""


class NonFiniteError(WmmError, ValueError):
    """An array argument holds NaN or infinity."""


class UnknownFrameError(WmmError, KeyError):
    """A frame name is not in the model."""

    def __str__(self):  # KeyError quotes its message; keep it readable.
        return str(self.args[0]) if self.args else ''
