"""The emitter of engine tests: :class:`engines.base.CollectingEmitter` (solutions, progress)."""

from __future__ import annotations

from engines.base import CollectingEmitter as Collect

__all__ = ["Collect"]
