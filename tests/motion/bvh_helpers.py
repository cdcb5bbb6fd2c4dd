"""Shared helpers for the BVH tests.

Everything here is deliberately independent of the code under test: a BVH text builder, a plain
token reader and a forward kinematics written with per-axis rotation matrices (no
``motion.rotations``, no ``scipy.spatial.transform.Rotation``, no ``motion.numparse``).

Conventions (as in the BVH files and DESIGN.md): rotation channels are intrinsic Euler angles in
file order, degrees, so ``CHANNELS ... Zrotation Xrotation Yrotation`` means
``R = Rz(a0) @ Rx(a1) @ Ry(a2)``; position channels replace the joint's OFFSET on their axis.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]

TAIT_BRYAN_ORDERS = ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX")
POSITION_XYZ = ("Xposition", "Yposition", "Zposition")


# --------------------------------------------------------------------------------------------
# building BVH text
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class JointSpec:
    """One joint of a synthetic skeleton (``parent`` must precede the joint; -1 for the root)."""

    name: str
    parent: int
    offset: tuple[float, float, float]
    channels: tuple[str, ...]
    end_sites: tuple[tuple[float, float, float], ...] = ()


def rot_channels(order: str) -> tuple[str, ...]:
    """``"ZXY"`` -> ``("Zrotation", "Xrotation", "Yrotation")``."""
    return tuple(f"{a}rotation" for a in order)


def num_channels(joints: Sequence[JointSpec]) -> int:
    return sum(len(j.channels) for j in joints)


def bvh_text_from_spec(
    joints: Sequence[JointSpec],
    rows: Sequence[Sequence[float]] | Array,
    *,
    frame_time: str = "0.033333",
    indent: str = "\t",
    newline: str = "\n",
    sep: str = " ",
    number_format: str = "%.6f",
    frames: int | None = None,
) -> str:
    """BVH text of a skeleton and its channel rows (``frames`` overrides the declared count)."""
    lines: list[str] = ["HIERARCHY"]

    def num(x: float) -> str:
        return number_format % x

    def emit(j: int, depth: int) -> None:
        ind = indent * depth
        spec = joints[j]
        lines.append(f"{ind}{'ROOT' if spec.parent < 0 else 'JOINT'} {spec.name}")
        lines.append(f"{ind}{{")
        lines.append(f"{ind}{indent}OFFSET {' '.join(num(v) for v in spec.offset)}")
        lines.append(f"{ind}{indent}CHANNELS {len(spec.channels)} {' '.join(spec.channels)}".rstrip())
        for c, child in enumerate(joints):
            if child.parent == j and c != j:
                emit(c, depth + 1)
        for site in spec.end_sites:
            lines.append(f"{ind}{indent}End Site")
            lines.append(f"{ind}{indent}{{")
            lines.append(f"{ind}{indent}{indent}OFFSET {' '.join(num(v) for v in site)}")
            lines.append(f"{ind}{indent}}}")
        lines.append(f"{ind}}}")

    emit(0, 0)
    table = np.asarray(rows, dtype=np.float64).reshape(-1, num_channels(joints))
    lines.append("MOTION")
    lines.append(f"Frames: {table.shape[0] if frames is None else frames}")
    lines.append(f"Frame Time: {frame_time}")
    lines.extend(sep.join(num(v) for v in row) for row in table)
    return newline.join(lines) + newline


def random_channel_rows(joints: Sequence[JointSpec], n_frames: int, rng: np.random.Generator) -> Array:
    """Random channel values, rounded to 6 decimals (so that ``%.6f`` text holds them exactly):
    positions in [-50, 50], angles in [-179, 179] (the middle one of three in [-85, 85])."""
    cols: list[Array] = []
    for spec in joints:
        n_rot = sum(c.endswith("rotation") for c in spec.channels)
        k = 0
        for c in spec.channels:
            if c.endswith("position"):
                cols.append(rng.uniform(-50.0, 50.0, n_frames))
            else:
                middle = n_rot == 3 and k == 1
                cols.append(
                    rng.uniform(-85.0, 85.0, n_frames) if middle else rng.uniform(-179.0, 179.0, n_frames)
                )
                k += 1
    return np.round(np.stack(cols, axis=1), 6).astype(np.float64) if cols else np.zeros((n_frames, 0))


# --------------------------------------------------------------------------------------------
# an independent reader (well-formed files only; joint names are single tokens)
# --------------------------------------------------------------------------------------------


@dataclass
class RawBvh:
    """A BVH file as plain lists and arrays, read without the code under test."""

    names: list[str] = field(default_factory=list)
    parents: list[int] = field(default_factory=list)
    offsets: list[list[float]] = field(default_factory=list)
    channels: list[list[str]] = field(default_factory=list)
    end_site_parents: list[int] = field(default_factory=list)
    end_site_offsets: list[list[float]] = field(default_factory=list)
    frames: int = 0
    frame_time: float = 0.0
    values: Array = field(default_factory=lambda: np.zeros((0, 0)))


def read_raw_bvh(data: bytes) -> RawBvh:
    """Parse a well-formed BVH file with a simple token reader (Python ``float`` for numbers)."""
    text = data.decode("latin-1")
    head, sep, body = text.partition("\nMOTION")
    if not sep:
        raise AssertionError("reference reader: no MOTION line")
    raw = RawBvh()
    toks = head.split()
    stack: list[int] = []  # joint index, or -1 for an End Site block
    i = 0
    while i < len(toks):
        t = toks[i]
        if t in ("ROOT", "JOINT"):
            raw.names.append(toks[i + 1])
            raw.parents.append(stack[-1] if stack else -1)
            raw.offsets.append([0.0, 0.0, 0.0])
            raw.channels.append([])
            stack.append(len(raw.names) - 1)
            i += 2  # the '{' is skipped below
        elif t == "End":
            raw.end_site_parents.append(stack[-1])
            raw.end_site_offsets.append([0.0, 0.0, 0.0])
            stack.append(-1)
            i += 2  # "End Site"
        elif t == "OFFSET":
            vals = [float(v) for v in toks[i + 1 : i + 4]]
            if stack[-1] < 0:
                raw.end_site_offsets[-1] = vals
            else:
                raw.offsets[stack[-1]] = vals
            i += 4
        elif t == "CHANNELS":
            n = int(toks[i + 1])
            raw.channels[stack[-1]] = toks[i + 2 : i + 2 + n]
            i += 2 + n
        elif t == "}":
            stack.pop()
            i += 1
        else:  # HIERARCHY, stray '{'
            i += 1
    btoks = body.split()
    # Frames: N Frame Time: T
    if btoks[0] != "Frames:" or btoks[2:4] != ["Frame", "Time:"]:
        raise AssertionError(f"reference reader: unexpected MOTION header {btoks[:5]}")
    raw.frames = int(btoks[1])
    raw.frame_time = float(btoks[4])
    n_ch = sum(len(c) for c in raw.channels)
    table = np.array(list(map(float, btoks[5:])), dtype=np.float64)
    if table.size != raw.frames * n_ch:
        raise AssertionError(f"reference reader: {table.size} values for {raw.frames} x {n_ch} channels")
    raw.values = table.reshape(raw.frames, n_ch)
    return raw


# --------------------------------------------------------------------------------------------
# rotations as matrices, written out per axis
# --------------------------------------------------------------------------------------------


def axis_matrix(axis: str, degrees: Array) -> Array:
    """``(..., 3, 3)`` rotation matrices about ``axis`` ("X", "Y" or "Z") by ``degrees``.

    X: [[1, 0, 0], [0, c, -s], [0, s, c]]; Y: [[c, 0, s], [0, 1, 0], [-s, 0, c]];
    Z: [[c, -s, 0], [s, c, 0], [0, 0, 1]].
    """
    r = np.radians(np.asarray(degrees, dtype=np.float64))
    c, s = np.cos(r), np.sin(r)
    m = np.zeros((*r.shape, 3, 3))
    if axis == "X":
        m[..., 0, 0] = 1.0
        m[..., 1, 1], m[..., 1, 2] = c, -s
        m[..., 2, 1], m[..., 2, 2] = s, c
    elif axis == "Y":
        m[..., 0, 0], m[..., 0, 2] = c, s
        m[..., 1, 1] = 1.0
        m[..., 2, 0], m[..., 2, 2] = -s, c
    elif axis == "Z":
        m[..., 0, 0], m[..., 0, 1] = c, -s
        m[..., 1, 0], m[..., 1, 1] = s, c
        m[..., 2, 2] = 1.0
    else:
        raise ValueError(f"bad axis {axis!r}")
    return m


def euler_matrix(order: str, degrees: Array) -> Array:
    """Intrinsic Euler angles ``(..., len(order))`` -> matrices ``R(order[0]) @ R(order[1]) @ ...``."""
    deg = np.asarray(degrees, dtype=np.float64)
    m = np.broadcast_to(np.eye(3), (*deg.shape[:-1], 3, 3)).copy()
    for k, axis in enumerate(order):
        m = m @ axis_matrix(axis, deg[..., k])
    return m


def quat_to_matrix(q: Array) -> Array:
    """Unit quaternions ``(x, y, z, w)`` -> rotation matrices (textbook formula)."""
    x, y, z, w = (q[..., i] for i in range(4))
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], axis=-1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], axis=-1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], axis=-1),
        ],
        axis=-2,
    )


def rotation_angle(a: Array, b: Array) -> Array:
    """Angle (radians) of ``a^T b`` for rotation matrices, accurate for small angles.

    ``||a - b||_F = 2 sqrt(2) sin(theta / 2)``, which keeps full precision near 0 (unlike arccos
    of the trace).
    """
    d = np.linalg.norm(np.asarray(a) - np.asarray(b), axis=(-2, -1))
    return np.asarray(2.0 * np.arcsin(np.clip(d / (2.0 * np.sqrt(2.0)), 0.0, 1.0)))


# --------------------------------------------------------------------------------------------
# independent forward kinematics
# --------------------------------------------------------------------------------------------


@dataclass
class RefPose:
    """Global positions ``(F, J, 3)``, rotations ``(F, J, 3, 3)`` and End Sites ``(F, E, 3)``."""

    positions: Array
    rotations: Array
    end_sites: Array


def local_transforms(
    channels: Sequence[Sequence[str]], offsets: Array, values: Array
) -> tuple[list[Array], list[Array]]:
    """Per joint: local rotation matrices ``(F, 3, 3)`` and translations ``(F, 3)`` from raw channels."""
    n_frames = values.shape[0]
    rots: list[Array] = []
    trans: list[Array] = []
    col = 0
    for j, chans in enumerate(channels):
        t = np.repeat(np.asarray(offsets[j], dtype=np.float64)[None, :], n_frames, axis=0)
        r: Array | None = None
        for c in chans:
            v = values[:, col]
            if c.endswith("position"):
                t[:, "XYZ".index(c[0])] = v
            else:
                m = axis_matrix(c[0], v)
                r = m if r is None else r @ m
            col += 1
        rots.append(np.broadcast_to(np.eye(3), (n_frames, 3, 3)).copy() if r is None else r)
        trans.append(t)
    return rots, trans


def reference_fk(raw: RawBvh, frames: slice | npt.NDArray[np.intp] | None = None) -> RefPose:
    """Global joint and End Site positions of ``raw`` (optionally on a subset of frames)."""
    values = raw.values if frames is None else raw.values[frames]
    rots, trans = local_transforms(raw.channels, np.asarray(raw.offsets), values)
    n_frames, n_joints = values.shape[0], len(raw.names)
    gpos = np.zeros((n_frames, n_joints, 3))
    grot = np.zeros((n_frames, n_joints, 3, 3))
    for j, p in enumerate(raw.parents):
        if p < 0:
            gpos[:, j] = trans[j]
            grot[:, j] = rots[j]
        else:
            gpos[:, j] = gpos[:, p] + np.einsum("fab,fb->fa", grot[:, p], trans[j])
            grot[:, j] = grot[:, p] @ rots[j]
    ends = np.zeros((n_frames, len(raw.end_site_parents), 3))
    for e, (p, off) in enumerate(zip(raw.end_site_parents, raw.end_site_offsets, strict=True)):
        ends[:, e] = gpos[:, p] + grot[:, p] @ np.asarray(off, dtype=np.float64)
    return RefPose(gpos, grot, ends)


def reference_height(positions: Array) -> float:
    """Median over frames of the vertical (Y) extent of the points ``(F, P, 3)``."""
    y = positions[..., 1]
    return float(np.median(y.max(axis=-1) - y.min(axis=-1)))


def under_static_root(bvh: str, root: str = "joint_Root") -> str:
    """The same motion under a static ground node, as Bandai-Namco rigs have it: a new ROOT
    ``root`` with six channels that stay zero, and the old root as its child joint."""
    head, motion = bvh.split("MOTION", 1)
    body = head.split("ROOT", 1)[1]
    indented = "\n".join(
        "  " + line if line.strip() else line for line in ("JOINT" + body).rstrip().splitlines()
    )
    hierarchy = (
        f"HIERARCHY\nROOT {root}\n{{\n  OFFSET 0 0 0\n"
        "  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n"
        f"{indented}\n}}\n"
    )
    lines = motion.strip("\n").splitlines()
    frames = [("0 0 0 0 0 0 " + line) for line in lines[2:] if line.strip()]
    return hierarchy + "MOTION\n" + lines[0] + "\n" + lines[1] + "\n" + "\n".join(frames) + "\n"
