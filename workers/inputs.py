"""Input files of a synthesis request (a control BVH, a MIDI song...): resolved and attached.

A request names its files with :meth:`schemas.bases.JobRequestBase.input_files`. Through the API
every reference is resolved at submission to the id of an upload (clip or file) and recorded in the
request's ``inputs``, so the job reads exactly the bytes it was submitted with; the CLI reads them
from paths relative to the request file.
"""

from __future__ import annotations

from pathlib import Path

from motion import MotionError
from motion.samples import resolve_path
from schemas.bases import JobRequestBase

from .store import NotFoundError, Store, Visible

MAX_INPUT_BYTES = 256 * 1024 * 1024
"""Largest input file the CLI reads (the API's upload limit applies to uploads)."""


class InputError(ValueError):
    """An input file that cannot be found or read; the message names the reference. ``code`` is
    the API error code (``input_not_found``, ``input_not_audio``)."""

    def __init__(self, message: str, code: str = "input_not_found") -> None:
        super().__init__(message)
        self.code = code


def resolve_inputs(
    store: Store, request: JobRequestBase, visible: Visible | None = None, holder: str | None = None
) -> dict[str, str]:
    """Reference -> upload id for every input file of ``request`` (ids given in ``inputs`` are
    checked, ``sample:NAME`` stores the bundled sample, the others are looked up by id or name
    among the uploads ``visible`` accepts, by ``holder``'s own names when given). Raises
    :class:`InputError` naming a missing one."""
    from .samples import store_sample

    resolved: dict[str, str] = {}
    for ref in request.input_files():
        given = request.inputs.get(ref, ref)
        try:
            sample = store_sample(store, given)
        except MotionError as exc:
            raise InputError(f"input file {ref!r}: {exc}") from None
        if sample is not None:
            resolved[ref] = sample[0]
            continue
        try:
            resolved[ref] = store.find_input(given, visible, holder)
        except NotFoundError as exc:
            raise InputError(f"input file {ref!r}: {exc}") from None
    _check_audio(store, request, resolved)
    return resolved


def _check_audio(store: Store, request: JobRequestBase, resolved: dict[str, str]) -> None:
    """Refuse, at submission, a recording input whose content is not WAV, FLAC, Ogg or MP3 (its
    first bytes only: decoding happens in the worker)."""
    for ref in request.audio_inputs():
        try:
            media = store.file_info(resolved[ref]).media_type
        except NotFoundError:
            media = "application/x-bvh"  # a clip
        if not media.startswith("audio/") or media == "audio/midi":
            raise InputError(
                f"input file {ref!r} is not a WAV, FLAC, Ogg or MP3 recording (its content is {media})",
                "input_not_audio",
            )


def attach_resolved(store: Store, request: JobRequestBase) -> None:
    """Attach the bytes of every input file from the store, by the upload ids of
    ``request.inputs`` (resolved with :func:`resolve_inputs`)."""
    files = {}
    for ref in request.input_files():
        try:
            files[ref] = store.input_bytes(request.inputs[ref])
        except (KeyError, NotFoundError) as exc:
            raise InputError(f"input file {ref!r}: {exc} (was it deleted after submission?)") from None
    request.attach_inputs(files)


def attach_from_dir(request: JobRequestBase, base: Path) -> None:
    """Attach the bytes of every input file from paths relative to ``base`` (the request file's
    folder; absolute paths are used as they are, ``sample:NAME`` names a bundled sample)."""
    files = {}
    for ref in request.input_files():
        try:
            path = resolve_path(ref, base)
        except MotionError as exc:
            raise InputError(f"input file {ref!r}: {exc}") from None
        try:
            size = path.stat().st_size
            if size > MAX_INPUT_BYTES:
                raise InputError(f"input file {ref!r} is {size} bytes (limit {MAX_INPUT_BYTES})")
            files[ref] = path.read_bytes()
        except OSError as exc:
            raise InputError(f"input file {ref!r} ({path}): {exc.strerror or exc}") from None
    request.attach_inputs(files)
