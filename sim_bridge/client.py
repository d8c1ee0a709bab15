"""Ownership of one PyBullet physics client: close it once, on exit or when collected."""

import pybullet as p

__all__ = ['OwnedClient']


class OwnedClient:
    """Base of the objects that own a PyBullet client (``self._cid``, -1 once closed).

    Use them as context managers, or call :meth:`close`.
    """

    _cid = -1

    def close(self) -> None:
        """Disconnect from PyBullet; safe to call twice."""
        if self._cid >= 0:
            p.disconnect(physicsClientId=self._cid)
            self._cid = -1

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):
        try:
            self.close()
        except Exception:  # interpreter shutdown: pybullet may already be gone
            return
