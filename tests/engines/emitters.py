"""An :class:`engines.base.Emitter` for engine tests: keeps every solution and progress message."""

from __future__ import annotations

from engines.base import Solution


class Collect:
    """Records what an engine reports; ``solution`` returns result ids ``r1, r2, ...``."""

    def __init__(self) -> None:
        self.solutions: list[Solution] = []
        self.progress_events: list[tuple[float, str]] = []

    @property
    def messages(self) -> list[str]:
        return [message for _, message in self.progress_events]

    def solution(self, solution: Solution) -> str:
        self.solutions.append(solution)
        return f"r{len(self.solutions)}"

    def progress(self, fraction: float, message: str = "") -> None:
        self.progress_events.append((fraction, message))
