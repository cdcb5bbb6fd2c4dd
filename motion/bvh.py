"""BVH reading and writing.

The reader accepts any per-joint channel order and count (position channels on any joint), End
Sites, tabs or spaces, CRLF or LF line ends, and gzip-compressed files (``.bvh.gz``, detected by
content). What common exporters write besides (a ``Frames:`` count that disagrees with the frame
lines, decimal commas, leaf joints without End Sites) is read and reported as a
:class:`~motion.errors.ReadWarning` naming the line (:func:`parse_bvh`); every problem that
cannot be read unambiguously is a :class:`~motion.errors.BvhError` naming the line. The MOTION block is
parsed by :func:`motion.numparse.parse_decimals` (one compiled pass, exact); files outside its plain
decimal grammar take a line-by-line path that also pinpoints bad lines.

Rotation channels are intrinsic Euler angles in file order, in degrees; position channels replace
the joint's OFFSET on their axis (as in the CMU and Bandai-Namco files).
"""

from __future__ import annotations

import gzip
import io
import math
import os
import re
import zlib
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace
from itertools import takewhile
from pathlib import Path
from typing import IO

import numpy as np
import numpy.typing as npt

from . import rotations as rot
from .errors import BvhError, ExportError, MotionError, ReadWarning
from .kinematics import FRAME_BLOCK
from .motion import Motion
from .numparse import parse_decimals_into
from .skeleton import VALID_CHANNELS, Skeleton
from .units import METRES_PER_UNIT, UnitGuess, guess_units, standing_height, up_axis

Array = npt.NDArray[np.float64]

DEFAULT_MAX_JOINTS = 1024
DEFAULT_MAX_FRAMES = 2_000_000
DEFAULT_MAX_BYTES = 1 << 30
DEFAULT_MAX_JOINT_FRAMES = 20_000_000
"""Default bound on frames x joints of one file: the reader holds ~100 bytes per joint-frame at
its peak (the channel table, the quaternions and the text), so ~2 GB here."""
_FPS_SNAP = 1e-3
MAX_ABS_VALUE = 1e9
"""Largest magnitude accepted for any channel value (any unit): beyond it a file is corrupt, and
kinematics would overflow."""  # snap 1/frame_time to an integer rate within this relative tolerance


@dataclass(frozen=True, slots=True)
class BvhLimits:
    """Limits that protect the reader from hostile or absurd files.

    ``max_joint_frames`` bounds frames x joints, what the reader's memory grows with: the header's
    ``Frames:`` is checked against it before any row is read, and the frame lines actually
    present (which win over the header) as they are counted, so a file's claim alone never sizes
    an allocation."""

    max_joints: int = DEFAULT_MAX_JOINTS
    max_frames: int = DEFAULT_MAX_FRAMES
    max_bytes: int = DEFAULT_MAX_BYTES
    max_joint_frames: int = DEFAULT_MAX_JOINT_FRAMES

    def max_rows(self, joints: int) -> int:
        """Most frames a file of ``joints`` joints may hold under these limits."""
        return min(self.max_frames, self.max_joint_frames // max(joints, 1))


# --------------------------------------------------------------------------------------------
# reading
# --------------------------------------------------------------------------------------------


def read_bvh(
    path: str | Path,
    *,
    units: str | None = None,
    limits: BvhLimits | None = None,
    name: str | None = None,
    warnings: list[ReadWarning] | None = None,
) -> Motion:
    """Read a BVH file (plain or gzip-compressed).

    Parameters
    ----------
    path:
        File path; ``.bvh`` or ``.bvh.gz`` (gzip is detected from the content).
    units:
        Declared length unit of the file (``"m"``, ``"cm"``, ...); guessed from the standing
        height when omitted (see :mod:`motion.units`).
    limits:
        Joint, frame and byte limits (defaults: 1024 joints, 2,000,000 frames, 1 GiB).
    name:
        Name recorded on the motion (default: the file name without ``.bvh``/``.gz``).
    warnings:
        When given, what the reader accepted from a file that does not follow BVH to the letter
        is appended to it (:class:`~motion.errors.ReadWarning`, see :func:`parse_bvh`).

    Returns
    -------
    The motion, positions in the file's unit, Y up.

    Raises
    ------
    BvhError
        For any unreadable or invalid content, naming the file and line.
    """
    p = Path(path)
    lim = limits or BvhLimits()
    try:
        with open(p, "rb") as fh:
            size = os.fstat(fh.fileno()).st_size
            if size > lim.max_bytes:
                raise BvhError(f"file is larger than the {lim.max_bytes}-byte limit", source=str(p))
            raw = fh.read()
    except OSError as exc:
        raise BvhError(f"cannot read file: {exc.strerror or exc}", source=str(p)) from None
    stem = p.name
    for suffix in (".gz", ".bvh"):
        stem = stem.removesuffix(suffix)
    return parse_bvh(
        raw,
        units=units,
        limits=lim,
        source=str(p),
        name=name if name is not None else stem,
        warnings=warnings,
    )


def parse_bvh(
    data: bytes,
    *,
    units: str | None = None,
    limits: BvhLimits | None = None,
    source: str = "<bytes>",
    name: str = "",
    joints: Sequence[str] | None = None,
    warnings: list[ReadWarning] | None = None,
) -> Motion:
    """Parse BVH content (bytes, plain or gzip). See :func:`read_bvh` for the parameters.

    ``joints``: when given, the motion of only these joints (those the file has) and their
    ancestors, a sub-skeleton without End Sites, for callers that need a few joints of a long clip
    (the other joints' rotations are never computed); the file is checked as a whole and the units
    are guessed from the whole skeleton, as without ``joints``.

    What common exporters write is read, and each departure from the format is reported in
    ``warnings`` (when a list is given) with its line: a ``Frames:`` count that disagrees with the
    frame lines (the lines present win), decimal commas (``0,5``: read as ``0.5`` when no number
    of the section uses a point), a leaf joint without an End Site or an End Site beside child
    joints. Tabs, CRLF line ends, blank lines, trailing spaces and a UTF-8 byte order mark
    are BVH as usual and read silently. What cannot be read unambiguously (a frame line with
    another number of values than the channels, a value that is not a number, a broken
    hierarchy) is a :class:`BvhError` naming the line and what to fix.

    Memory: the header's frames x joints is checked against ``limits.max_joint_frames`` before
    any row is read (a gzip file is inflated no further than its first 16 MiB then), the frame lines
    present are counted against it before the table is allocated, and the rows are parsed into
    that one preallocated ``(F, C)`` array."""
    lim = limits or BvhLimits()
    if units is not None and units not in METRES_PER_UNIT:
        raise BvhError(f"unknown units {units!r}; use one of {', '.join(METRES_PER_UNIT)}", source=source)
    notes: list[ReadWarning] = [] if warnings is None else warnings
    data = _maybe_gunzip(bytes(data), lim, source)
    if data.startswith(b"\xef\xbb\xbf"):  # a UTF-8 byte order mark (Windows editors)
        data = data[3:]
    if len(data) > lim.max_bytes:
        raise BvhError(f"file is larger than the {lim.max_bytes}-byte limit", source=source)
    m = _MOTION.search(data)
    if m is None:
        if not data.strip():
            raise BvhError("file is empty", source=source)
        _parse_hierarchy(_decode(data, source), lim, source)  # a broken hierarchy is the better message
        raise BvhError("no MOTION section", line=_line_count(data), source=source)
    header_text = _decode(data[: m.start()], source)
    skeleton = _parse_hierarchy(header_text, lim, source, notes)
    motion_line = data.count(b"\n", 0, m.start()) + 1
    head = _parse_motion_header(data, m.end(), motion_line, lim, source, skeleton.num_joints, notes)
    table = _parse_table(data, head, skeleton, lim, source, notes)
    n_frames = table.shape[0]
    fps = 1.0 / head.frame_time
    if abs(fps - round(fps)) <= _FPS_SNAP * fps:
        fps = float(round(fps))
    if joints is None:
        motion = _motion_from_channels(skeleton, table, fps, name, source)
        return motion.with_units(units if units is not None else detect_units(motion).units)
    if units is None:  # from the whole skeleton, on the frames detect_units would sample
        sample = _motion_from_channels(skeleton, table[:: _unit_step(n_frames)], fps, name, source)
        units = _units_of_sample(sample)
    sub, columns = _sub_skeleton(skeleton, [skeleton.names.index(j) for j in joints if j in skeleton.names])
    return _motion_from_channels(sub, table[:, columns], fps, name, source).with_units(units)


_MOTION = re.compile(rb"(?m)^[ \t]*MOTION\b")


def _line_count(data: bytes) -> int:
    """The line number of the last line of ``data``."""
    return data.count(b"\n") + 1


def _sub_skeleton(skeleton: Skeleton, joints: list[int]) -> tuple[Skeleton, npt.NDArray[np.intp]]:
    """The skeleton of ``joints`` and their ancestors (joint order kept, End Sites dropped) and the
    columns of a frame table that hold their channels."""
    keep = np.zeros(skeleton.num_joints, dtype=bool)
    keep[0] = True
    for j in joints:
        while j >= 0 and not keep[j]:
            keep[j] = True
            j = int(skeleton.parents[j])
    chosen = np.flatnonzero(keep)
    index = np.full(skeleton.num_joints, -1, dtype=np.intp)
    index[chosen] = np.arange(chosen.size)
    first = np.concatenate(([0], np.cumsum([len(c) for c in skeleton.channels])))
    columns = np.concatenate([np.arange(first[j], first[j + 1]) for j in chosen]).astype(np.intp)
    parents = np.where(skeleton.parents[chosen] >= 0, index[skeleton.parents[chosen]], -1)
    sub = Skeleton(
        tuple(skeleton.names[j] for j in chosen),
        parents,
        skeleton.offsets[chosen],
        tuple(skeleton.channels[j] for j in chosen),
    )
    return sub, columns


def _unit_step(num_frames: int) -> int:
    """Every how many frames :func:`detect_units` samples a motion (about 240 frames in all)."""
    return max(1, num_frames // 240)


def detect_units(motion: Motion, up: int | None = 1) -> UnitGuess:
    """Standing height of a motion (its own unit) along the ``up`` axis (1: Y, as Segue reads a
    BVH; 2: Z; None: detected, :func:`motion.units.up_axis`) and the unit guess (see
    :mod:`motion.units`)."""
    step = _unit_step(motion.num_frames)
    sample = motion if step == 1 else _subsample(motion, step)
    if up == 1:
        return _guess_of_sample(sample)
    points = _frame_points(sample)
    return guess_units(standing_height(points, up_axis(points) if up is None else up))


def height_m(motion: Motion, up: int | None = 1) -> float:
    """The motion's height in metres, Segue's one definition of it (inspect, retarget, a clip's
    ``height_m``): its standing height (:func:`motion.units.standing_height`: the median over
    frames of the vertical extent of joints and End Sites, on about 240 frames) along ``up`` (as
    :func:`detect_units`), converted with the motion's unit (a motion of unknown unit: its
    guessed one). A one-frame motion (a character's rest pose) is measured on that frame."""
    guess = detect_units(motion, up)
    if motion.units == "unknown":
        return guess.height_m
    return guess.height * motion.metres_per_unit


def detect_up_axis(motion: Motion) -> int:
    """The vertical axis of a motion's file (1: Y, 2: Z; :func:`motion.units.up_axis`)."""
    step = _unit_step(motion.num_frames)
    return up_axis(_frame_points(motion if step == 1 else _subsample(motion, step)))


def _frame_points(sample: Motion) -> npt.NDArray[np.float64]:
    pos, grot = sample.fk()
    return np.concatenate((pos, sample.end_site_positions(pos, grot)), axis=1)


def _units_of_sample(sample: Motion) -> str:
    """:func:`detect_units`' unit of a motion already sampled (every :func:`_unit_step` frames)."""
    return _guess_of_sample(sample).units


def _guess_of_sample(sample: Motion) -> UnitGuess:
    pos, grot = sample.fk()
    frame_points = np.concatenate((pos, sample.end_site_positions(pos, grot)), axis=1)
    return guess_units(standing_height(frame_points))


def _subsample(motion: Motion, step: int) -> Motion:
    s = slice(None, None, step)
    return replace(
        motion,
        root_positions=motion.root_positions[s],
        rotations=motion.rotations[s],
        joint_translations=motion.joint_translations[s],
    )


INFLATE_CHUNK_BYTES = 1 << 20
"""Largest piece :func:`inflate_chunks` inflates at a time (bounds its memory beside the input)."""


def inflate_chunks(data: bytes, limit: int, source: str, chunk: int = INFLATE_CHUNK_BYTES) -> Iterator[bytes]:
    """The inflated pieces of gzip ``data`` (all members, as ``gzip`` does), each at most ``chunk``
    bytes; :class:`BvhError` past ``limit`` inflated bytes, for a truncated or corrupt stream, or for
    trailing garbage (the header check streams them; :func:`parse_bvh` joins them)."""
    size, rest = 0, data
    try:
        while rest:
            d = zlib.decompressobj(16 + zlib.MAX_WBITS)
            pending = rest
            while True:
                piece = d.decompress(pending, chunk)
                size += len(piece)
                if size > limit:
                    raise BvhError(f"decompressed file is larger than the {limit}-byte limit", source=source)
                if piece:
                    yield piece
                if d.eof:  # the member's end: what follows it is in unused_data (and, once the
                    break  # output limit has cut a call, still in unconsumed_tail: not to be fed again)
                pending = d.unconsumed_tail
                if not pending and not piece:
                    break
            if not d.eof:
                raise BvhError("gzip stream is truncated", source=source)
            rest = d.unused_data
            if rest and not rest.startswith(b"\x1f\x8b"):
                if rest.strip(b"\x00"):
                    raise BvhError("trailing garbage after the gzip data", source=source)
                break
    except zlib.error as exc:
        raise BvhError(f"corrupt gzip data ({exc})", source=source) from None


def _maybe_gunzip(data: bytes, lim: BvhLimits, source: str) -> bytes:
    """Decompress gzip content (all members, as ``gzip`` does), within the byte limit. The
    header (HIERARCHY and the ``Frames:`` / ``Frame Time:`` lines) is checked once 16 MiB are
    inflated, so that a file whose header breaks a limit (``Frames: 1900000`` in a 0.9 MB gzip)
    is refused before the rest of its rows are inflated."""
    if not data.startswith(b"\x1f\x8b"):
        return data
    pieces: list[bytes] = []
    size, checked = 0, False
    for piece in inflate_chunks(data, lim.max_bytes, source):
        pieces.append(piece)
        size += len(piece)
        if not checked and size >= _EARLY_CHECK_BYTES:  # smaller files: the parse checks it
            checked = _header_checked(b"".join(pieces)[:_HEADER_SCAN_BYTES], lim, source)
    return b"".join(pieces)


_EARLY_CHECK_BYTES = 16 << 20
"""Inflated bytes after which :func:`_maybe_gunzip` checks a gzip file's header before going on
(below, inflating it all costs less than parsing the header twice)."""


def _header_checked(view: bytes, lim: BvhLimits, source: str) -> bool:
    """Whether the start of BVH text ``view`` (its first :data:`_HEADER_SCAN_BYTES`) holds its
    whole header, once checked against the limits (:class:`BvhError` when it breaks one); False
    while the header is not all there."""
    if view.startswith(b"\xef\xbb\xbf"):
        view = view[3:]
    m = _MOTION.search(view)
    if m is None or _MOTION_HEADER.match(view, m.end()) is None:
        return len(view) >= _HEADER_SCAN_BYTES  # no header that early: the parse says what is wrong
    # the same parsers and text as the whole parse: a header error here is the one it would give
    skeleton = _parse_hierarchy(_decode(view[: m.start()], source), lim, source)
    motion_line = view.count(b"\n", 0, m.start()) + 1
    _parse_motion_header(view, m.end(), motion_line, lim, source, skeleton.num_joints, [])
    return True


_HEADER_SCAN_BYTES = 4 << 20
"""Inflated bytes of a gzip file in which :func:`_maybe_gunzip` looks for the header."""


def _decode(raw: bytes, source: str) -> str:
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


def _tokens(text: str) -> Iterator[tuple[str, int, list[str]]]:
    """Yield ``(token, line_number, rest_of_line_tokens)`` for every whitespace token."""
    for lineno, line in enumerate(text.split("\n"), start=1):
        toks = line.split()
        for i, tok in enumerate(toks):
            yield tok, lineno, toks[i + 1 :]


def _parse_float(tok: str, lineno: int, what: str, source: str) -> float:
    try:
        v = float(tok)
    except ValueError:
        raise BvhError(f"{what}: {tok!r} is not a number", lineno, source) from None
    if not math.isfinite(v) or abs(v) > MAX_ABS_VALUE:
        raise BvhError(f"{what}: {tok!r} is not a finite number within +-{MAX_ABS_VALUE:g}", lineno, source)
    return v


_DECIMAL_COMMA = re.compile(r"[-+]?[0-9]*,[0-9]+")
"""A number written with a decimal comma (``-0,5``, ``12,25``): one comma, digits after it."""


def _decimal_comma(tok: str) -> float | None:
    """The value of a token written with a decimal comma, else None."""
    return float(tok.replace(",", ".")) if _DECIMAL_COMMA.fullmatch(tok) else None


def _parse_hierarchy(
    text: str, lim: BvhLimits, source: str, notes: list[ReadWarning] | None = None
) -> Skeleton:
    """The skeleton of a BVH file's HIERARCHY section (:class:`BvhError` naming the line); the
    departures it reads (decimal commas in OFFSETs, leaf joints without End Sites, End Sites
    beside child joints) are appended to ``notes``."""
    parser = _HierarchyParser(lim, source)
    skeleton = parser.parse(text)
    if notes is not None:
        notes.extend(parser.notes(skeleton))
    return skeleton


END_SITE = -2
"""What an End Site block's entry on the block stack is (joint blocks push their joint index)."""


class _HierarchyParser:
    """HIERARCHY as a token stream: ``ROOT``/``JOINT name`` and ``End Site`` open a pending block
    that the next ``{`` pushes on a stack, ``OFFSET`` and ``CHANNELS`` fill the block on top, ``}``
    closes it after checking it is complete."""

    def __init__(self, lim: BvhLimits, source: str) -> None:
        self.lim, self.source = lim, source
        self.names: list[str] = []
        self.parents: list[int] = []
        self.offsets: list[list[float] | None] = []
        self.channels: list[tuple[str, ...] | None] = []
        self.es_parents: list[int] = []
        self.es_offsets: list[list[float]] = []
        self.stack: list[int] = []  # joint index, or END_SITE
        self.pending: tuple[str, int | None, int] | None = None  # (kind, joint index, line) awaiting '{'
        self.end_site_offset: list[float] | None = None
        self.it: Iterator[tuple[str, int, list[str]]] = iter(())
        self.comma_line: int | None = None  # the first OFFSET written with decimal commas
        self.lines: list[int] = []  # the line of each joint's ROOT/JOINT
        self.end_site_lines: list[int] = []

    def error(self, message: str, lineno: int | None) -> BvhError:
        return BvhError(message, lineno, self.source)

    def parse(self, text: str) -> Skeleton:
        self.it = _tokens(text)
        seen_hierarchy = False
        last_line = 1
        for tok, lineno, rest in self.it:
            last_line = lineno
            if not seen_hierarchy:
                if tok != "HIERARCHY":
                    raise self.error(f"expected HIERARCHY, found {tok!r}", lineno)
                seen_hierarchy = True
                continue
            if self.pending is not None and tok != "{":
                raise self.error(f"expected '{{' after {self.pending[0]}, found {tok!r}", lineno)
            if tok in ("ROOT", "JOINT"):
                self.joint(tok, lineno, rest)
            elif tok == "End":
                self.end_site(lineno, rest)
            elif tok == "{":
                self.open_block(lineno)
            elif tok == "}":
                self.close_block(lineno)
            elif tok == "OFFSET":
                self.offset(lineno, rest)
            elif tok == "CHANNELS":
                self.channel_list(lineno, rest)
            else:
                raise self.error(f"unexpected {tok!r} in HIERARCHY", lineno)
        if not seen_hierarchy:
            raise self.error("missing HIERARCHY", 1)
        if self.pending is not None or self.stack:
            raise self.error("HIERARCHY ends inside an open block (missing '}')", last_line)
        if not self.names:
            raise self.error("HIERARCHY has no ROOT", last_line)
        return self.skeleton()

    def joint(self, tok: str, lineno: int, rest: list[str]) -> None:
        """``ROOT name`` / ``JOINT name``: a new joint, child of the block on top."""
        if tok == "ROOT" and (self.names or self.stack):
            raise self.error("only one ROOT per file is supported", lineno)
        if tok == "JOINT" and (not self.stack or self.stack[-1] < 0):
            raise self.error("JOINT outside a joint block", lineno)
        words = list(takewhile(lambda w: w != "{", rest))
        if not words:
            raise self.error(f"{tok} without a name", lineno)
        name = " ".join(words)
        if name in self.names:
            raise self.error(f"duplicate joint name {name!r}", lineno)
        if len(self.names) >= self.lim.max_joints:
            raise self.error(f"more than the {self.lim.max_joints}-joint limit", lineno)
        self.names.append(name)
        self.lines.append(lineno)
        self.parents.append(self.stack[-1] if self.stack else -1)
        self.offsets.append(None)
        self.channels.append(None)
        self.pending = (tok, len(self.names) - 1, lineno)
        _skip(self.it, len(words))

    def end_site(self, lineno: int, rest: list[str]) -> None:
        """``End Site``: a leaf of the joint block on top."""
        if not self.stack or self.stack[-1] < 0:
            raise self.error("End Site outside a joint block", lineno)
        self.pending = ("End Site", None, lineno)
        self.end_site_lines.append(lineno)
        self.end_site_offset = None
        _skip(self.it, len(list(takewhile(lambda w: w != "{", rest))))

    def open_block(self, lineno: int) -> None:
        if self.pending is None:
            raise self.error("unexpected '{'", lineno)
        self.stack.append(self.pending[1] if self.pending[1] is not None else END_SITE)
        self.pending = None

    def close_block(self, lineno: int) -> None:
        """``}``: the block on top is complete (an OFFSET, and CHANNELS for a joint)."""
        if not self.stack:
            raise self.error("unbalanced '}'", lineno)
        top = self.stack.pop()
        if top == END_SITE:
            if self.end_site_offset is None:
                raise self.error("End Site without OFFSET", lineno)
            self.es_parents.append(self.stack[-1])
            self.es_offsets.append(self.end_site_offset)
            return
        if self.offsets[top] is None:
            raise self.error(f"joint {self.names[top]!r} has no OFFSET", lineno)
        if self.channels[top] is None:
            raise self.error(f"joint {self.names[top]!r} has no CHANNELS", lineno)

    def offset(self, lineno: int, rest: list[str]) -> None:
        """``OFFSET x y z`` of the block on top (file units)."""
        if not self.stack:
            raise self.error("OFFSET outside a joint block", lineno)
        if len(rest) < 3:
            raise self.error(f"OFFSET needs 3 numbers, found {len(rest)}", lineno)
        vals = []
        for t in rest[:3]:
            comma = _decimal_comma(t)
            if comma is not None and self.comma_line is None:
                self.comma_line = lineno
            vals.append(comma if comma is not None else _parse_float(t, lineno, "OFFSET", self.source))
        top = self.stack[-1]
        if top == END_SITE:
            self.end_site_offset = vals
        else:
            if self.offsets[top] is not None:
                raise self.error(f"second OFFSET for joint {self.names[top]!r}", lineno)
            self.offsets[top] = vals
        _skip(self.it, 3)

    def channel_list(self, lineno: int, rest: list[str]) -> None:
        """``CHANNELS n name...`` of the joint block on top."""
        if not self.stack or self.stack[-1] < 0:
            raise self.error("CHANNELS outside a joint block", lineno)
        j = self.stack[-1]
        chans = _channel_names(rest, lineno, self.source)
        if self.channels[j] is not None:
            raise self.error(f"second CHANNELS for joint {self.names[j]!r}", lineno)
        self.channels[j] = chans
        _skip(self.it, 1 + len(chans))

    def notes(self, skeleton: Skeleton) -> list[ReadWarning]:
        """The departures from BVH this hierarchy was read with (see :func:`parse_bvh`)."""
        out: list[ReadWarning] = []
        if self.comma_line is not None:
            out.append(
                ReadWarning(
                    "decimal_comma",
                    "OFFSET numbers are written with decimal commas (0,5): read as decimal points",
                    self.comma_line,
                    self.source,
                )
            )
        has_child = np.zeros(len(self.names), dtype=bool)
        has_child[[p for p in self.parents if p >= 0]] = True
        sites = np.bincount(np.asarray(self.es_parents, dtype=np.intp), minlength=len(self.names))
        bare = [j for j in range(len(self.names)) if not has_child[j] and sites[j] == 0]
        if bare:
            shown = ", ".join(repr(self.names[j]) for j in bare[:6]) + (", ..." if len(bare) > 6 else "")
            s = "s" if len(bare) > 1 else ""
            out.append(
                ReadWarning(
                    "missing_end_site",
                    f"{len(bare)} leaf joint{s} without an End Site ({shown}): read as they are; the last "
                    "bone of each has no length, so the height may read a little short",
                    self.lines[bare[0]],
                    self.source,
                )
            )
        beside = [j for j in range(len(self.names)) if sites[j] > 1 or (sites[j] and has_child[j])]
        if beside:
            shown = ", ".join(repr(self.names[j]) for j in beside[:6]) + (", ..." if len(beside) > 6 else "")
            first = min(ln for p, ln in zip(self.es_parents, self.end_site_lines, strict=True) if p in beside)
            out.append(
                ReadWarning(
                    "extra_end_site",
                    f"End Sites beside child joints or several under one joint ({shown}): each is kept as "
                    "the tip of a bone",
                    first,
                    self.source,
                )
            )
        return out

    def skeleton(self) -> Skeleton:
        """The parsed skeleton, End Sites by parent joint (stable: the order the writer emits them in)."""
        es_order = np.argsort(np.array(self.es_parents, dtype=np.intp), kind="stable")
        try:
            return Skeleton(
                tuple(self.names),
                np.array(self.parents, dtype=np.intp),
                np.array(self.offsets, dtype=np.float64),
                tuple(c or () for c in self.channels),
                np.array(self.es_parents, dtype=np.intp)[es_order],
                np.array(self.es_offsets, dtype=np.float64).reshape(-1, 3)[es_order],
            )
        except MotionError as exc:
            raise self.error(str(exc), None) from None


def _channel_names(rest: list[str], lineno: int, source: str) -> tuple[str, ...]:
    """The channels of a ``CHANNELS`` line after the keyword: a count 0..6, then that many distinct
    valid channel names."""
    if not rest:
        raise BvhError("CHANNELS without a count", lineno, source)
    try:
        count = int(rest[0])
    except ValueError:
        raise BvhError(f"CHANNELS count {rest[0]!r} is not an integer", lineno, source) from None
    if not 0 <= count <= 6:
        raise BvhError(f"CHANNELS count {count} is outside 0..6", lineno, source)
    chans = rest[1 : 1 + count]
    listed = len(list(takewhile(lambda t: t in VALID_CHANNELS, rest[1:])))
    if listed > count:
        raise BvhError(f"CHANNELS declares {count} channels but lists {listed}", lineno, source)
    if len(chans) != count:
        raise BvhError(f"CHANNELS declares {count} channels but lists {len(chans)}", lineno, source)
    bad = [c for c in chans if c not in VALID_CHANNELS]
    if bad:
        raise BvhError(f"unknown channel {bad[0]!r} (expected X/Y/Z position/rotation)", lineno, source)
    if len(set(chans)) != len(chans):
        raise BvhError("a channel is listed twice", lineno, source)
    return tuple(chans)


def _skip(it: Iterator[tuple[str, int, list[str]]], n: int) -> None:
    for _ in range(n):
        next(it, None)


_MOTION_HEADER = re.compile(
    rb"[ \t\r]*\n?\s*(?i:frames)[ \t]*:[ \t]*(\S*)[^\n]*\n"
    rb"\s*(?i:frame)[ \t]*(?i:time)[ \t]*:[ \t]*(\S*)[^\n]*(?:\n|\Z)"
)
"""The ``Frames: N`` and ``Frame Time: T`` lines after ``MOTION`` (keywords in any case, spaces or
tabs around the colon, as exporters write them)."""


@dataclass(frozen=True, slots=True)
class _MotionHeader:
    """What the MOTION section's header says: the declared ``frames`` (on line ``frames_line``),
    ``frame_time`` (s), and where the frame lines start (byte ``data_start``, line ``data_line``)."""

    frames: int
    frame_time: float
    data_start: int
    data_line: int
    frames_line: int


def _parse_motion_header(
    data: bytes,
    pos: int,
    motion_line: int,
    lim: BvhLimits,
    source: str,
    n_joints: int,
    notes: list[ReadWarning],
) -> _MotionHeader:
    """The ``Frames:`` and ``Frame Time:`` lines after MOTION (at byte ``pos``), the declared
    frames checked against the frame and joint-frame limits (:class:`BvhError` naming the line)."""
    m = _MOTION_HEADER.match(data, pos)
    if m is None:
        raise BvhError("expected 'Frames: N' and 'Frame Time: T' after MOTION", motion_line + 1, source)
    frames_line = motion_line + data.count(b"\n", pos, m.start(1))
    time_line = motion_line + data.count(b"\n", pos, m.start(2))
    frames_tok = m.group(1).decode("latin-1")
    time_tok = m.group(2).decode("latin-1")
    try:
        n_frames = int(frames_tok)
    except ValueError:
        raise BvhError(f"Frames: {frames_tok!r} is not an integer", frames_line, source) from None
    if n_frames < 0:
        raise BvhError(f"Frames: {n_frames} is negative", frames_line, source)
    if n_frames > lim.max_frames:
        raise BvhError(f"Frames: {n_frames} is over the {lim.max_frames}-frame limit", frames_line, source)
    if n_frames * max(n_joints, 1) > lim.max_joint_frames:
        raise BvhError(
            f"Frames: {n_frames} x {n_joints} joints = {n_frames * n_joints:,} joint-frames is over the "
            f"{lim.max_joint_frames:,} joint-frame limit: split the clip into shorter files",
            frames_line,
            source,
        )
    comma = _decimal_comma(time_tok)
    if comma is not None:
        frame_time = comma
        notes.append(
            ReadWarning(
                "decimal_comma",
                f"Frame Time {time_tok} is written with a decimal comma: read as {comma:g} s",
                time_line,
                source,
            )
        )
    else:
        frame_time = _parse_float(time_tok, time_line, "Frame Time", source)
    if not 1e-5 <= frame_time <= 10.0:
        raise BvhError(f"Frame Time: {frame_time} s is not a plausible frame interval", time_line, source)
    data_line = time_line + 1 if m.group(0).endswith(b"\n") else time_line
    return _MotionHeader(n_frames, frame_time, m.end(), data_line, frames_line)


def _parse_table(
    data: bytes,
    head: _MotionHeader,
    skeleton: Skeleton,
    lim: BvhLimits,
    source: str,
    notes: list[ReadWarning],
) -> Array:
    """``(F, C)`` channel values of the frame lines after the MOTION header: ``F`` the lines
    present (blank ones skipped), whatever ``Frames:`` declares (a warning says so when they
    differ); at most :meth:`BvhLimits.max_rows` of them (else :class:`BvhError`).

    The table is allocated once, ``rows x C`` for the lines counted (newlines: blank lines make
    it a few rows larger than needed at worst, and a count past the limit is made exact before it
    is refused), and the values are parsed into it: by the compiled or vectorised decimal parser
    (:func:`motion.numparse.parse_decimals_into`), by a line-by-line pass for numbers outside its
    grammar (exponents, ``+`` signs), which also names a bad line."""
    start, n_channels = head.data_start, skeleton.num_channels
    max_rows = lim.max_rows(skeleton.num_joints)
    rows = data.count(b"\n", start) + 1  # lines after the header: frame lines and blank ones
    if rows > max_rows:
        rows = _count_rows(data, start)
        if rows > max_rows:
            raise BvhError(
                f"the file holds {rows} frame lines (Frames: says {head.frames}) x {skeleton.num_joints} "
                f"joints: over the {max_rows}-frame limit of this skeleton (max_frames {lim.max_frames}, "
                f"max_joint_frames {lim.max_joint_frames:,}); split the clip into shorter files",
                head.frames_line,
                source,
            )
    if n_channels == 0:  # no values: as many (blank) frames as declared
        if head.frames == 0:
            raise BvhError("file ends after 0 of the 0 declared frames", _line_count(data), source)
        return np.empty((head.frames, 0))
    table = np.empty((rows, n_channels))
    flat = table.reshape(-1)
    block = data
    count = parse_decimals_into(block, flat, start, row_length=n_channels)
    if count is None and _uses_decimal_commas(data, start):
        block = data[:start] + data[start:].replace(b",", b".")  # same length: same lines and offsets
        notes.append(
            ReadWarning(
                "decimal_comma",
                "frame values are written with decimal commas (0,5): read as decimal points",
                head.data_line,
                source,
            )
        )
        count = parse_decimals_into(block, flat, start, row_length=n_channels)
    found = -1
    if count is not None:
        held = table[: count // n_channels]
        if count == 0 or (float(held.max()) <= MAX_ABS_VALUE and float(held.min()) >= -MAX_ABS_VALUE):
            found = count // n_channels  # else a huge value: the line-by-line pass names it
    if found < 0:
        found = _parse_rows(block, head, table, source)
    if found == 0:
        raise BvhError(f"file ends after 0 of the {head.frames} declared frames", _line_count(data), source)
    if found != head.frames:
        notes.append(
            ReadWarning(
                "frame_count",
                f"Frames: {head.frames}, but the file holds {found} frame lines: read {found} (the lines "
                "present win)",
                head.frames_line,
                source,
            )
        )
    if found == rows:
        return table
    # blank lines were counted: a view of the rows, or a copy when most of the table is unused
    return table[:found].copy() if 2 * found < rows else table[:found]


def _uses_decimal_commas(data: bytes, start: int) -> bool:
    """Whether the frame lines from byte ``start`` write decimal commas unambiguously: commas and
    no decimal point anywhere (a section mixing both, or using commas between numbers, is not read
    this way: the line-by-line pass then names the first bad value)."""
    return data.find(b",", start) >= 0 and data.find(b".", start) < 0


_COUNT_CHUNK = 1 << 20


def _count_rows(data: bytes, start: int) -> int:
    """Non-blank lines of ``data`` from byte ``start`` (counted a MiB at a time)."""
    count, pos, end = 0, start, len(data)
    while pos < end:
        stop = data.find(b"\n", min(pos + _COUNT_CHUNK, end))
        stop = end if stop < 0 else stop + 1
        count += sum(1 for line in data[pos:stop].split(b"\n") if line.strip())
        pos = stop
    return count


def _parse_rows(data: bytes, head: _MotionHeader, table: Array, source: str) -> int:
    """The frame lines parsed one by one into ``table`` (which has room for them all): the rows
    written, or :class:`BvhError` naming the first line with the wrong count of values, a value that
    is not a number or not finite within +-:data:`MAX_ABS_VALUE`."""
    n_channels = table.shape[1]
    row, pos, end = 0, head.data_start, len(data)
    lineno = head.data_line
    last_line_start = data.rstrip().rfind(b"\n") + 1
    row_lines: list[int] = []  # only filled when a value is out of range (to name its line)
    while pos < end:
        nl = data.find(b"\n", pos)
        stop = end if nl < 0 else nl
        toks = data[pos:stop].split()
        if toks:
            if len(toks) != n_channels:
                cut = (
                    " (the file seems cut short here: delete this line to read the frames before it)"
                    if pos >= last_line_start and len(toks) < n_channels
                    else ""
                )
                raise BvhError(
                    f"frame {row} has {len(toks)} values, expected {n_channels} (one per channel){cut}",
                    lineno,
                    source,
                )
            try:
                table[row] = list(map(float, toks))
            except ValueError:
                bad = next(t for t in toks if not _is_float(t))
                mixed = b"," in bad
                hint = " (decimal commas beside decimal points: write one or the other)" if mixed else ""
                raise BvhError(
                    f"frame {row}: {bad.decode('latin-1')!r} is not a number{hint}", lineno, source
                ) from None
            row += 1
        pos = stop + 1
        lineno += 1
    held = table[:row]
    if row and not (float(held.max()) <= MAX_ABS_VALUE and float(held.min()) >= -MAX_ABS_VALUE):
        bad_row = int(np.flatnonzero(~np.all(np.abs(held) <= MAX_ABS_VALUE, axis=1))[0])
        row_lines = [
            head.data_line + k for k, line in enumerate(data[head.data_start :].split(b"\n")) if line.strip()
        ]
        raise BvhError(
            f"frame {bad_row}: a value is not finite or beyond +-{MAX_ABS_VALUE:g}",
            row_lines[bad_row],
            source,
        )
    return row


def _is_float(tok: bytes) -> bool:
    try:
        float(tok)
    except ValueError:
        return False
    return True


RotationGroups = dict[str, tuple[list[int], list[list[int]]]]
"""Rotation channels by Euler order: ``{order: (joints, their channel columns)}``."""


def _channel_layout(skeleton: Skeleton) -> tuple[list[tuple[int, int, int]], RotationGroups]:
    """Where a skeleton's channels sit in a BVH frame row: ``(joint, axis, column)`` of every
    position channel, and the rotation channels grouped by Euler order (one vectorised
    conversion per order)."""
    positions: list[tuple[int, int, int]] = []
    groups: RotationGroups = {}
    col = 0
    for j, chans in enumerate(skeleton.channels):
        rot_cols: list[int] = []
        order = ""
        for c in chans:
            if c.endswith("position"):
                positions.append((j, "XYZ".index(c[0]), col))
            else:
                rot_cols.append(col)
                order += c[0]
            col += 1
        if order:
            joints, cols = groups.setdefault(order, ([], []))
            joints.append(j)
            cols.append(rot_cols)
    return positions, groups


def _motion_from_channels(skeleton: Skeleton, table: Array, fps: float, name: str, source: str) -> Motion:
    n_frames = table.shape[0]
    root_pos = np.broadcast_to(skeleton.offsets[0], (n_frames, 3)).copy()
    translated = skeleton.translated_joints
    jt = np.broadcast_to(skeleton.offsets[translated], (n_frames, translated.size, 3)).copy()
    slot = {int(j): k for k, j in enumerate(translated)}
    positions, groups = _channel_layout(skeleton)
    for j, axis, col in positions:
        if j == 0:
            root_pos[:, axis] = table[:, col]
        else:
            jt[:, slot[j], axis] = table[:, col]
    # Quaternions are written in a (4, J, F) layout, frame block by frame block (small, cached
    # temporaries); the motion keeps the (F, J, 4) transposed view, which FK reads for free.
    q_soa = np.zeros((4, skeleton.num_joints, n_frames))
    q_soa[3] = 1.0
    compiled = [(order, joints, np.array(cols)) for order, (joints, cols) in groups.items()]
    for f0 in range(0, n_frames, FRAME_BLOCK):
        block_t = np.ascontiguousarray(table[f0 : f0 + FRAME_BLOCK].T)  # (C, B)
        for order, joints, col_idx in compiled:
            comps = rot.from_euler_components(order, [block_t[col_idx[:, k]] for k in range(len(order))])
            for axis in range(4):
                q_soa[axis, joints, f0 : f0 + FRAME_BLOCK] = comps[axis]
    quats = np.transpose(q_soa, (2, 1, 0))
    return Motion(skeleton, root_pos, quats, fps, jt, "unknown", name)


# --------------------------------------------------------------------------------------------
# writing
# --------------------------------------------------------------------------------------------


def channel_table(motion: Motion) -> Array:
    """``(F, C)`` BVH channel values of a motion, in its skeleton's channel layout.

    Rotations become intrinsic Euler angles in each joint's order (see :func:`rotations.to_euler`);
    a joint without rotation channels must not rotate (:class:`ExportError` otherwise).
    """
    sk = motion.skeleton
    n_frames = motion.num_frames
    table = np.empty((n_frames, sk.num_channels))
    slot = {int(j): k for k, j in enumerate(sk.translated_joints)}
    positions, groups = _channel_layout(sk)
    for j, axis, col in positions:
        src = motion.root_positions if j == 0 else motion.joint_translations[:, slot[j]]
        table[:, col] = src[:, axis]
    rotated = {j for joints, _ in groups.values() for j in joints}
    for j in range(sk.num_joints):
        if j not in rotated and np.any(rot.angle_between(motion.rotations[:, j], rot.IDENTITY) > 1e-6):
            raise ExportError(f"joint {sk.names[j]!r} rotates but has no rotation channels")
    for order, (joints, cols) in groups.items():
        angles = rot.to_euler(order, motion.rotations[:, joints])
        table[:, np.array(cols)] = angles
    return table


def write_bvh(motion: Motion, dest: str | Path | IO[str], *, precision: int = 6) -> None:
    """Write a motion as BVH text (gzip-compressed when the path ends in ``.gz``).

    Parameters
    ----------
    motion:
        The motion; lengths are written in its units.
    dest:
        A path or a text stream.
    precision:
        Decimals written for every number (6 keeps a read-write-read round trip within 5e-7).
    """
    text = bvh_text(motion, precision=precision)
    if isinstance(dest, (str, Path)):
        p = Path(dest)
        if p.name.endswith(".gz"):
            with gzip.open(p, "wt", encoding="utf-8", newline="\n") as fh:
                fh.write(text)
        else:
            p.write_text(text, encoding="utf-8", newline="\n")
    else:
        dest.write(text)


def bvh_text(motion: Motion, *, precision: int = 6) -> str:
    """The BVH text of a motion (see :func:`write_bvh`)."""
    sk = motion.skeleton
    fmt = f"%.{precision}f"
    out = io.StringIO()
    out.write("HIERARCHY\n")
    children: list[list[int]] = [[] for _ in range(sk.num_joints)]
    for j in range(1, sk.num_joints):
        children[int(sk.parents[j])].append(j)
    sites: list[list[int]] = [[] for _ in range(sk.num_joints)]
    for e, p in enumerate(sk.end_site_parents):
        sites[int(p)].append(e)

    def vec(v: npt.NDArray[np.float64]) -> str:
        return " ".join(fmt % x for x in v)

    def emit(j: int, depth: int) -> None:
        ind = "\t" * depth
        out.write(f"{ind}{'ROOT' if j == 0 else 'JOINT'} {sk.names[j]}\n{ind}{{\n")
        out.write(f"{ind}\tOFFSET {vec(sk.offsets[j])}\n")
        chans = sk.channels[j]
        out.write(f"{ind}\tCHANNELS {len(chans)}{''.join(' ' + c for c in chans)}\n")
        for c in children[j]:
            emit(c, depth + 1)
        for e in sites[j]:
            out.write(
                f"{ind}\tEnd Site\n{ind}\t{{\n{ind}\t\tOFFSET {vec(sk.end_site_offsets[e])}\n{ind}\t}}\n"
            )
        out.write(f"{ind}}}\n")

    emit(0, 0)
    table = channel_table(motion)
    out.write(f"MOTION\nFrames: {motion.num_frames}\nFrame Time: {1.0 / motion.fps:.{max(precision, 6)}f}\n")
    if table.shape[1]:
        row = " ".join([fmt] * table.shape[1]) + "\n"
        out.write((row * table.shape[0]) % tuple(table.ravel().tolist()))
    else:
        out.write("\n" * table.shape[0])
    return out.getvalue()
