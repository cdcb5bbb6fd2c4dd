"""Errors raised by the motion core.

Every problem with user input surfaces as a subclass of :class:`MotionError`, never as a bare
``IndexError``/``ValueError``, so callers (CLI, service) can turn it into a clear message.
"""

from __future__ import annotations


class MotionError(ValueError):
    """Invalid motion data or an impossible request on valid data."""


class BvhError(MotionError):
    """A BVH file could not be read.

    Attributes
    ----------
    line:
        1-based line number in the file where the problem was found, or ``None`` when the problem is
        not tied to one line (e.g. the file is empty or over a size limit).
    problem:
        The problem, without the line prefix.
    source:
        The file name (or ``"<string>"``), for messages.
    """

    def __init__(self, problem: str, line: int | None = None, source: str = "<string>") -> None:
        self.problem = problem
        self.line = line
        self.source = source
        where = f"{source}:{line}" if line is not None else source
        super().__init__(f"{where}: {problem}")


class ExportError(MotionError):
    """A motion could not be written in the requested format or convention."""
