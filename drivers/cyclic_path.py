"""The control cycle's path through a medium that can batch (``drivers/transport.py`` looks for
it): ``stage`` a frame, ``flush`` the staged ones together, ``drain_frames`` what came. Here
the part both media share: the count of staged frames."""

from __future__ import annotations


class StagedFrames:
    """A batch being staged: ``staged`` frames, taken (and reset) by ``_take_staged``."""

    _staged = 0

    @property
    def staged(self) -> int:
        """Frames staged for the next ``flush``."""
        return self._staged

    def _take_staged(self) -> int:
        """The frames staged so far, the batch emptied (a flush is sending them)."""
        n, self._staged = self._staged, 0
        return n
