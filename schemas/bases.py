"""Base models every engine's specs and requests extend (kept apart so engine schema modules can
import them without cycles)."""

from __future__ import annotations

from typing import Self

from pydantic import Field, PrivateAttr

from .clips import ClipSource
from .common import Strict


class DatabaseSpecBase(Strict):
    """Settings every database kind shares."""

    kind: str
    clips: list[ClipSource] = Field(min_length=1, max_length=100_000)
    fps: float | None = Field(default=None, ge=1, le=1000, description="resample every clip to this rate")
    name: str | None = Field(default=None, max_length=128)


class JobRequestBase(Strict):
    """Settings every synthesis request shares."""

    engine: str = Field(description="the engine that answers the request (each model fixes its own)")
    database: str | None = Field(
        default=None, description="database id (API); the CLI's --db directory supplies it otherwise"
    )
    budget_s: float = Field(
        default=10.0,
        gt=0,
        le=3600,
        description="safety cap on the search's time, seconds: every search is bounded by work the "
        "request sets (graph 'rounds', annotations 'passes', control stages, rhythm one pass), so a "
        "request and seed give the same answer on any machine; when this cap cuts the work short, the "
        '\'done\' event and the report say "stopped": "budget" (the answer may differ from an '
        "unhurried run's)",
    )
    seed: int = Field(default=0, ge=0, le=2**32 - 1)
    inputs: dict[str, str] = Field(
        default_factory=dict,
        max_length=64,
        description="input files resolved to uploads: reference as written in the request -> id of the "
        "uploaded clip or file (the API fills it at submission, so a job always reads the bytes it was "
        "submitted with)",
    )

    _inputs: dict[str, bytes] = PrivateAttr(default_factory=dict)

    def input_files(self) -> list[str]:
        """References to the input files this request reads (control BVH, MIDI...), as written in
        the request: a path relative to the request file (CLI) or an uploaded file's id or name
        (API). Engines with file inputs override this; the runtime resolves every reference and
        attaches the bytes (:meth:`attach_inputs`) before the engine runs."""
        return []

    def with_budget(self, budget_s: float) -> Self:
        """A copy of this request with ``budget_s`` (seconds) replaced, validated as the field is when
        a request is parsed (pydantic's ``ValidationError`` naming ``budget_s`` otherwise): the CLI's
        ``--budget`` overrides the request's cap this way."""
        copy = self.model_copy()
        self.__pydantic_validator__.validate_assignment(copy, "budget_s", budget_s)
        return copy

    def audio_inputs(self) -> list[str]:
        """The input files that must be music recordings (checked at submission by their first
        bytes); engines that read recordings override this."""
        return []

    def named_joints(self) -> list[tuple[str, str]]:
        """``(where, joint name)`` of every joint the request names, to check against the database's
        skeleton at submission; engines whose requests name joints override this."""
        return []

    def named_labels(self) -> list[tuple[str, str, bool]]:
        """``(where, label, required)`` of every label the request names, to check against the
        database's label vocabulary at submission: ``required`` labels must be in it (an unknown
        one is a 422), others may be absent (asking not to carry a label nobody has is fine).
        Engines whose requests name labels override this."""
        return []

    def named_clip_frames(self) -> list[tuple[str, str, int]]:
        """``(where, clip name, frame)`` of every database clip frame the request names (pose and
        frame constraints, an excerpt's last frame), frames at the database rate, to check against
        the database's clips at submission. Engines whose requests name clips override this."""
        return []

    def attach_inputs(self, files: dict[str, bytes]) -> None:
        """Give the request the bytes of its input files, keyed by reference."""
        self._inputs.update(files)

    def input_bytes(self, ref: str) -> bytes:
        """The bytes of an input file; ``KeyError`` naming the reference when it was not resolved."""
        try:
            return self._inputs[ref]
        except KeyError:
            raise KeyError(f"input file {ref!r} was not provided with the request") from None
