"""Spatial queries' names for the shared thread policy (:func:`unmesh._threads.serial_if_small`).

No policy of its own: :data:`SERIAL_BELOW` and :func:`serial_if_small` are those of
:mod:`unmesh._threads` (kept for ``kdtree`` and ``neighbors``, which import them from here).
"""

from __future__ import annotations

from unmesh._threads import SERIAL_BELOW, serial_if_small

__all__ = ["SERIAL_BELOW", "serial_if_small"]
