"""Errors raised by the motion core.

Every problem with user input surfaces as a subclass of :class:`MotionError`, never as a bare
``IndexError``/``ValueError``, so callers (CLI, service) can turn it into a clear message.
"""

from __future__ import annotations

from dataclasses import dataclass


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


class GltfError(MotionError):
    """A glTF file (GLB, or ``.gltf`` with its buffers) could not be read as a motion or a
    character."""


class ExportError(MotionError):
    """A motion could not be written in the requested format or convention."""


@dataclass(frozen=True, slots=True)
class ReadWarning:
    """Something a reader accepted from a file that does not follow its format to the letter (a
    frame count that disagrees with the frame lines, decimal commas, a leaf joint without an End
    Site...): the file was read, and the user should know how.

    Attributes
    ----------
    code:
        A short stable name of the quirk (``"frame_count"``, ``"decimal_comma"``, ...).
    problem:
        What was found and how it was read, one sentence without the file and line prefix.
    line:
        1-based line of the file it concerns, or ``None``.
    source:
        The file name, for messages.
    """

    code: str
    problem: str
    line: int | None = None
    source: str = "<string>"

    @property
    def message(self) -> str:
        """``problem`` with the line in front (``"line 130: ..."``), without the file name."""
        return f"line {self.line}: {self.problem}" if self.line is not None else self.problem

    def __str__(self) -> str:
        where = f"{self.source}:{self.line}" if self.line is not None else self.source
        return f"{where}: {self.problem}"
