"""What a BVH file is, from its header and a streaming pass, in bounded memory.

:func:`bvh_header` reads the HIERARCHY and the ``Frames:`` / ``Frame Time:`` lines of a BVH file
(plain or gzip) without parsing its MOTION table: the joints, channels, frames and rate a budget
needs (frames x joints) and the header errors :func:`motion.bvh.parse_bvh` would give, with the
same messages (it uses the same hierarchy and motion-header parsers). A gzip file is inflated
chunk by chunk and the inflated bytes are counted and dropped, so a gzip bomb costs CPU bounded by
``limits.max_bytes`` and memory bounded by :data:`CHUNK_BYTES` + :data:`MAX_HEADER_BYTES`.

This is the check an API process can afford on an upload; the full parse (every number of the
table) runs in a worker.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass

from .bvh import _FPS_SNAP, BvhLimits, _decode, _parse_hierarchy, _parse_motion_header, inflate_chunks
from .errors import BvhError

MAX_HEADER_BYTES = 4 << 20
"""Most bytes of a BVH header (HIERARCHY + MOTION lines) read before giving up: 1,024 joints of a
verbose exporter take ~0.3 MB."""
CHUNK_BYTES = 1 << 20
"""Inflated bytes held at once while a gzip file is measured."""

_MOTION = re.compile(rb"(?m)^[ \t]*MOTION\b")


@dataclass(frozen=True, slots=True)
class BvhHeader:
    """A BVH file's shape: ``joints`` (names, file order, End Sites excluded), ``channels`` per frame,
    ``frames`` (as the ``Frames:`` line declares them; the full parse reads the frame lines
    present, which win when they differ), ``fps`` (1 / Frame Time), ``text_bytes`` (bytes after
    gunzip) and ``lines`` (lines after the ``Frame Time:`` line, blank ones included: a bound on
    the frames the full parse can find)."""

    joints: tuple[str, ...]
    channels: int
    frames: int
    fps: float
    text_bytes: int
    lines: int = 0

    @property
    def frames_bound(self) -> int:
        """The most frames the full parse can read: the declared count or the lines present,
        whichever is larger."""
        return max(self.frames, self.lines)

    @property
    def joint_frames(self) -> int:
        """frames x joints: what a motion's arrays scale with."""
        return self.frames * len(self.joints)

    @property
    def duration_s(self) -> float:
        """Seconds from the first frame to the last (``(frames - 1) / fps``)."""
        return (self.frames - 1) / self.fps


def _inflated(data: bytes, limit: int, source: str) -> Iterator[bytes]:
    """The inflated chunks of gzip ``data`` (:func:`motion.bvh.inflate_chunks`, at most
    :data:`CHUNK_BYTES` each)."""
    return inflate_chunks(data, limit, source, CHUNK_BYTES)


def bvh_header(data: bytes, limits: BvhLimits | None = None, source: str = "<bytes>") -> BvhHeader:
    """The header facts of BVH ``data`` (plain or gzip), in bounded memory (module docstring).

    Raises :class:`~motion.errors.BvhError` for what the header shows: a bad hierarchy, too many
    joints, a missing or bad ``Frames:``/``Frame Time:``, more frames than ``limits.max_frames``,
    more bytes (after gunzip) than ``limits.max_bytes``. The table itself is not read."""
    lim = limits or BvhLimits()
    if data.startswith(b"\x1f\x8b"):
        head, total, newlines = bytearray(), 0, 0
        for chunk in _inflated(data, lim.max_bytes, source):
            total += len(chunk)
            newlines += chunk.count(b"\n")
            if len(head) < MAX_HEADER_BYTES:
                head += chunk[: MAX_HEADER_BYTES - len(head)]
        text = bytes(head)
    else:
        total = len(data)
        if total > lim.max_bytes:
            raise BvhError(f"file is larger than the {lim.max_bytes}-byte limit", source=source)
        text = data[:MAX_HEADER_BYTES]
        newlines = data.count(b"\n")
    offset = 3 if text.startswith(b"\xef\xbb\xbf") else 0
    if offset:
        text, total = text[offset:], total - offset
    m = _MOTION.search(text)
    if m is None:
        if not text.strip():
            raise BvhError("file is empty", source=source)
        _parse_hierarchy(_decode(text, source), lim, source)  # a broken hierarchy is the better message
        if total > len(text):
            raise BvhError(f"no MOTION section in the first {MAX_HEADER_BYTES} bytes", source=source)
        raise BvhError("no MOTION section", line=text.count(b"\n") + 1, source=source)
    skeleton = _parse_hierarchy(_decode(text[: m.start()], source), lim, source)
    motion_line = text.count(b"\n", 0, m.start()) + 1
    mh = _parse_motion_header(text, m.end(), motion_line, lim, source, skeleton.num_joints, [])
    fps = 1.0 / mh.frame_time
    if abs(fps - round(fps)) <= _FPS_SNAP * fps:  # as parse_bvh snaps it
        fps = float(round(fps))
    lines = max(0, newlines - text.count(b"\n", 0, mh.data_start)) + 1
    return BvhHeader(tuple(skeleton.names), skeleton.num_channels, mh.frames, fps, total, lines)


def _head_text(data: bytes, limit: int, source: str) -> bytes:
    """The first ``limit`` bytes of BVH text (inflating only what it takes)."""
    if not data.startswith(b"\x1f\x8b"):
        return data[:limit]
    head = bytearray()
    for chunk in _inflated(data, 1 << 62, source):
        head += chunk[: limit - len(head)]
        if len(head) >= limit:
            break
    return bytes(head)


def bvh_first_frames(data: bytes, frames: int = 1, source: str = "<bytes>") -> bytes | None:
    """BVH text of ``data`` (plain or gzip) cut after its first ``frames`` frames (its ``Frames:``
    line saying so), read from the first :data:`MAX_HEADER_BYTES` only; None when they are not
    there (a header or lines longer than that). Parsing it gives exactly the first frames of the
    whole file: what a character's rest pose needs of a clip, without reading its other frames."""
    from .bvh import _MOTION_HEADER

    text = _head_text(data, MAX_HEADER_BYTES, source)
    offset = 3 if text.startswith(b"\xef\xbb\xbf") else 0
    m = _MOTION.search(text, offset)
    if m is None:
        return None
    header = _MOTION_HEADER.match(text, m.end())
    if header is None:
        return None
    end = header.end()
    for _ in range(frames):
        nl = text.find(b"\n", end)
        if nl < 0:
            return None
        end = nl + 1
    return text[offset : header.start(1)] + str(frames).encode() + text[header.end(1) : end]
