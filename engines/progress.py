"""Progress of a long step made of phases, as one fraction that only moves forward.

A database build reads its clips, makes the motion library, runs the kind's own build (the motion
graph's features and transitions, the annotation SVMs, ...) and measures the examples; each part
reports its own progress from 0 to 1. :class:`PhasedProgress` gives each phase its span of the
overall [0, 1] and names it, so that a client sees ``"graph: features of 1816 frames"`` at 10 %,
never ``50 %`` followed by ``0 %``: a phase's fraction maps into its span, and the overall fraction
never goes back (a phase reporting less than before, or a later phase starting below where an
earlier one ended, holds the fraction where it was). Messages are ``"<phase>: <detail>"``.
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .base import Emitter, Solution


_NAMED = re.compile(r"^[a-z][a-z ]*: ")
"""A progress message that starts with the name of its step."""


class PhasedProgress:
    """An :class:`~engines.base.Emitter` whose progress is monotonic, reported by named phases
    (module docstring). ``progress(fraction, message)`` reports an overall fraction as is;
    :meth:`phase` gives an emitter for one phase's own fractions."""

    def __init__(self, emit: Emitter) -> None:
        self.emit = emit
        self.reached = 0.0

    @classmethod
    def of(cls, emit: Emitter) -> PhasedProgress:
        """``emit`` itself when it already is one (a build's phases nest), else a new one on it."""
        return emit if isinstance(emit, PhasedProgress) else cls(emit)

    def solution(self, solution: Solution) -> str:
        return self.emit.solution(solution)

    def progress(self, fraction: float, message: str = "") -> None:
        """Report the overall ``fraction`` (held at the highest reached) with ``message``."""
        self.reached = max(self.reached, min(max(float(fraction), 0.0), 1.0))
        self.emit.progress(self.reached, message)

    def report(self, fraction: float, phase: str, detail: str = "") -> None:
        """Report the overall ``fraction`` in ``phase`` (message ``"phase: detail"``)."""
        self.progress(fraction, f"{phase}: {detail}" if detail else phase)

    def phase(self, name: str, start: float, end: float) -> Phase:
        """An emitter for the phase ``name`` spanning ``[start, end]`` of the overall fraction."""
        if not 0.0 <= start <= end <= 1.0:
            raise ValueError(f"a phase spans part of [0, 1]: got [{start}, {end}]")
        return Phase(self, name, start, end)


class Phase:
    """One phase of a :class:`PhasedProgress`: ``progress(fraction, message)`` with the phase's
    own ``fraction`` in [0, 1]; a message that names its step already (``"graph: features"``,
    ``"movement graph: 12 groups"``: lower-case words and a colon) is kept as it is, any other gets
    the phase's name in front (``"motion beats"`` -> ``"rhythm: motion beats"``)."""

    def __init__(self, owner: PhasedProgress, name: str, start: float, end: float) -> None:
        self.owner, self.name, self.start, self.end = owner, name, start, end

    def solution(self, solution: Solution) -> str:
        return self.owner.solution(solution)

    def progress(self, fraction: float, message: str = "") -> None:
        f = self.start + (self.end - self.start) * min(max(float(fraction), 0.0), 1.0)
        if _NAMED.match(message) or message == self.name:
            self.owner.progress(f, message)
        else:
            self.owner.report(f, self.name, message)
