"""Export a :class:`~motion.motion.Motion` as a binary glTF 2.0 file (GLB).

The file holds one scene with a skinned skeleton and one animation, in glTF's convention, which is
also Segue's internal one: right-handed, Y up, metres, quaternions ``(x, y, z, w)``. Lengths are
converted with :attr:`Motion.metres_per_unit <motion.motion.Motion.metres_per_unit>` (a motion of
unknown units is written as if its unit were the metre).

Layout
------
GLB container
    12-byte header (``b"glTF"``, version 2, total length), a JSON chunk padded with spaces and a BIN
    chunk padded with zeros, both to 4 bytes. Every buffer view starts on a 4-byte boundary, and
    every accessor's ``byteOffset`` is a multiple of 4.
Nodes
    ``0 .. J-1``: one node per joint, in skeleton order (node index = joint index), named after the
    joint, with ``children`` following ``skeleton.parents`` and a rest transform made of the joint's
    offset (metres) alone (identity rotation, unit scale). Then one leaf node per End Site, named
    ``"<parent>_end"`` (``"<parent>_end_<k>"`` for further End Sites of the same joint), child of
    its joint but not a joint of the skin. Last, when a mesh is written, the mesh node
    (``mesh: 0``, ``skin: 0``, no transform), a root of the scene beside the skeleton root.
Ground root
    With ``ground_root=True`` the motion first gets an explicit ground root joint named
    ``"ground"`` by :func:`motion.ground.add_ground_root` (floor projection of the hips, rotated by
    the heading), so engines and game tools can take root motion. A motion whose root is already
    named ``"ground"`` (e.g. an engine's output) is exported as it is.
Animation
    One animation named after the motion (``"motion"`` when unnamed). One shared input accessor of
    key times ``frame / fps`` seconds; LINEAR samplers. Every joint gets a rotation channel (local
    quaternions, signs made continuous over time so that interpolation takes the short arc); the
    root and every joint of ``skeleton.translated_joints`` get a translation channel (metres).
    The quaternions of all joints sit in one buffer view, one accessor per joint; likewise the
    translations.
Skin
    ``joints`` = the ``J`` joint nodes (skin joint index = joint index), ``skeleton`` = node 0, and
    ``inverseBindMatrices`` (``MAT4``, column-major) = the inverse of each joint's global rest
    transform (rest pose: offsets, identity rotations, i.e. a pure translation).
Mesh (``mesh=True``)
    One primitive drawing every bone of the rest pose as a flat-shaded octahedron from the parent
    joint to the child joint (or End Site), its widest section a fifth of the way along, rigidly
    bound (weight 1) to the parent joint. Width: 3 % of the body size (the largest extent of the
    rest-pose bounding box, which is the standing height for an upright or T-pose rest and still
    the body length for a rest pose lying down), at most a quarter of the bone length, so that
    fingers stay slender. Zero-length bones and the link from the ground root to the hips are not
    drawn. Attributes: ``POSITION``, ``NORMAL`` (``FLOAT VEC3``), ``JOINTS_0`` (``UNSIGNED_SHORT
    VEC4``), ``WEIGHTS_0`` (``FLOAT VEC4``) and indices (``UNSIGNED_SHORT``, or ``UNSIGNED_INT``
    past 65,535 vertices), with one plain grey material.

Example
-------
>>> import motion
>>> from motion.export.glb import glb_bytes
>>> from motion.samples import sample_path
>>> clip = motion.read_bvh(sample_path("walk")).slice(0, 10)
>>> glb_bytes(clip)[:4]
b'glTF'
"""

from __future__ import annotations

import json
import struct
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from .. import rotations as rot
from ..errors import ExportError, MotionError
from ..ground import GROUND_ROOT_NAME, add_ground_root
from ..motion import Motion

Array = npt.NDArray[np.float64]

__all__ = ["glb_bytes", "write_glb"]

GLB_MAGIC = b"glTF"
GLB_VERSION = 2
CHUNK_JSON = 0x4E4F534A  # "JSON"
CHUNK_BIN = 0x004E4942  # "BIN\0"

# accessor component types and buffer view targets (glTF 2.0, section 5.1 / 5.11)
UNSIGNED_SHORT = 5123
UNSIGNED_INT = 5125
FLOAT = 5126
ARRAY_BUFFER = 34962
ELEMENT_ARRAY_BUFFER = 34963

BONE_WIDTH_OF_BODY = 0.03  # octahedron width as a fraction of the body size
BONE_WIDTH_OF_LENGTH = 0.25  # ... and at most this fraction of the bone's length
BONE_WAIST = 0.2  # position of the widest section along the bone, from the parent
_MIN_BONE_OF_BODY = 1e-6  # bones shorter than this fraction of the body size are not drawn
_MAX_SKIN_JOINTS = 65536  # JOINTS_0 is UNSIGNED_SHORT


def glb_bytes(motion: Motion, *, ground_root: bool = True, mesh: bool = True) -> bytes:
    """The motion as a binary glTF 2.0 file (see the module docstring for the layout).

    Parameters
    ----------
    motion:
        The motion to export, ``F >= 1`` frames, lengths in ``motion.units`` (converted to
        metres with ``motion.metres_per_unit``; unknown units count as metres).
    ground_root:
        Add an explicit ground root joint named ``"ground"`` with
        :func:`motion.ground.add_ground_root` (skipped when the root already has that name).
    mesh:
        Add a skinned bone mesh so that any viewer shows the character.

    Returns
    -------
    The GLB file content: right-handed, Y up, metres, key times in seconds.

    Raises
    ------
    ExportError
        When the motion has no frames, holds non-finite values or zero quaternions, has too many
        joints for ``JOINTS_0`` (65,536), its frame times do not increase in float32, or
        ``ground_root`` is asked for while a non-root joint is already called ``"ground"``.
    """
    m = _prepared(motion, ground_root)
    sk = m.skeleton
    scale = m.metres_per_unit
    b = _Builder()
    offsets = sk.offsets * scale
    rest = _rest_globals(sk.parents, offsets)  # (J, 3) metres
    nodes = _joint_nodes(m, offsets)
    scene_roots = [0]
    channels, samplers = _animation(b, m)  # buffer views in file order: animation, skin, mesh
    gltf: dict[str, Any] = {
        "asset": {"version": "2.0", "generator": "segue"},
        "scene": 0,
        "scenes": [{"name": _label(m), "nodes": scene_roots}],
        "nodes": nodes,
        "skins": [_skin(b, m, rest)],
        "animations": [{"name": _label(m), "channels": channels, "samplers": samplers}],
    }
    if mesh:
        _add_bone_mesh(b, gltf, m, rest)
    gltf["accessors"] = b.accessors
    gltf["bufferViews"] = b.views
    gltf["buffers"] = [{"byteLength": len(b.data)}]
    return _container(gltf, bytes(b.data))


def _joint_nodes(m: Motion, offsets: Array) -> list[dict[str, Any]]:
    """Nodes ``0 .. J-1`` (the joints, at their rest offsets ``(J, 3)`` metres) then one leaf per End
    Site, with ``children`` after ``skeleton.parents``."""
    sk = m.skeleton
    n_joints = sk.num_joints
    nodes: list[dict[str, Any]] = [
        {"name": name, "translation": _floats(offsets[j])} for j, name in enumerate(sk.names)
    ]
    children: list[list[int]] = [[] for _ in range(n_joints)]
    for j in range(1, n_joints):
        children[int(sk.parents[j])].append(j)
    end_count = [0] * n_joints
    for parent, off in zip(sk.end_site_parents, sk.end_site_offsets * m.metres_per_unit, strict=True):
        p = int(parent)
        suffix = "_end" if end_count[p] == 0 else f"_end_{end_count[p]}"
        end_count[p] += 1
        children[p].append(len(nodes))
        nodes.append({"name": sk.names[p] + suffix, "translation": _floats(off)})
    for j in range(n_joints):
        if children[j]:
            nodes[j]["children"] = children[j]
    return nodes


def _animation(b: _Builder, m: Motion) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """The animation's channels and samplers: key times ``frame / fps`` s, every joint's local
    quaternions (continuous signs) and the translations of the root and translated joints (m)."""
    sk = m.skeleton
    n_joints, n_frames = sk.num_joints, m.num_frames
    times = (np.arange(n_frames, dtype=np.float64) / m.fps).astype(np.float32)
    if n_frames > 1 and not np.all(np.diff(times) > 0):
        raise ExportError(
            f"frame times at {m.fps} fps do not increase in float32 over {n_frames} frames; "
            "resample the motion before exporting it to glTF"
        )
    time_view = b.view(times)
    t_acc = b.accessor(time_view, 0, FLOAT, n_frames, "SCALAR", times[:1], times[-1:])

    try:
        quats = rot.make_continuous(rot.normalize(m.rotations), axis=0)
    except MotionError as exc:
        raise ExportError(f"cannot export {_label(m)}: {exc}") from None
    quat_view = b.view(np.ascontiguousarray(np.swapaxes(quats, 0, 1)).astype(np.float32))  # (J, F, 4)
    rot_acc = [b.accessor(quat_view, j * n_frames * 16, FLOAT, n_frames, "VEC4") for j in range(n_joints)]

    moved = np.concatenate(([0], sk.translated_joints)).astype(np.intp)
    trans = np.concatenate((m.root_positions[:, None], m.joint_translations), axis=1) * m.metres_per_unit
    trans_view = b.view(np.ascontiguousarray(np.swapaxes(trans, 0, 1)).astype(np.float32))  # (1+K, F, 3)
    trans_acc = [
        b.accessor(trans_view, k * n_frames * 12, FLOAT, n_frames, "VEC3") for k in range(moved.size)
    ]

    samplers: list[dict[str, Any]] = []
    channels: list[dict[str, Any]] = []
    for node, acc, path in [
        *((j, rot_acc[j], "rotation") for j in range(n_joints)),
        *((int(j), trans_acc[k], "translation") for k, j in enumerate(moved)),
    ]:
        channels.append({"sampler": len(samplers), "target": {"node": node, "path": path}})
        samplers.append({"input": t_acc, "interpolation": "LINEAR", "output": acc})
    return channels, samplers


def _skin(b: _Builder, m: Motion, rest: Array) -> dict[str, Any]:
    """The skin: every joint node, inverse bind matrices = the inverse of the rest globals ``rest``
    ``(J, 3)`` (pure translations), column-major."""
    sk = m.skeleton
    n_joints = sk.num_joints
    ibm = np.broadcast_to(np.eye(4), (n_joints, 4, 4)).copy()
    ibm[:, :3, 3] = -rest  # inverse of a pure translation
    ibm_view = b.view(np.ascontiguousarray(np.swapaxes(ibm, 1, 2)).astype(np.float32))  # column-major
    return {
        "name": sk.names[0] + "_skin",
        "joints": list(range(n_joints)),
        "skeleton": 0,
        "inverseBindMatrices": b.accessor(ibm_view, 0, FLOAT, n_joints, "MAT4"),
    }


def _add_bone_mesh(b: _Builder, gltf: dict[str, Any], m: Motion, rest: Array) -> None:
    """Add the skinned bone mesh, its material and its node (a scene root) to ``gltf``."""
    sk = m.skeleton
    grounded = sk.names[0] == GROUND_ROOT_NAME  # True after _prepared(..., ground_root=True)
    geometry = _bone_mesh(
        sk.parents, rest, sk.end_site_parents, sk.end_site_offsets * m.metres_per_unit, grounded
    )
    if geometry is None:
        return
    gltf["meshes"] = [{"name": sk.names[0] + "_bones", "primitives": [_primitive(b, *geometry)]}]
    gltf["materials"] = [
        {
            "name": "bone",
            "pbrMetallicRoughness": {
                "baseColorFactor": [0.72, 0.74, 0.78, 1.0],
                "metallicFactor": 0.0,
                "roughnessFactor": 0.7,
            },
        }
    ]
    nodes = gltf["nodes"]
    gltf["scenes"][0]["nodes"].append(len(nodes))
    nodes.append({"name": sk.names[0] + "_mesh", "mesh": 0, "skin": 0})


def write_glb(motion: Motion, path: str | Path, *, ground_root: bool = True, mesh: bool = True) -> None:
    """Write :func:`glb_bytes` of the motion to ``path`` (conventionally ``*.glb``).

    Parameters
    ----------
    motion, ground_root, mesh:
        As for :func:`glb_bytes`.
    path:
        Destination file, overwritten if it exists.

    Raises
    ------
    ExportError
        For a motion that cannot be exported (see :func:`glb_bytes`) or a file that cannot be
        written.
    """
    data = glb_bytes(motion, ground_root=ground_root, mesh=mesh)
    p = Path(path)
    try:
        p.write_bytes(data)
    except OSError as exc:
        raise ExportError(f"cannot write {p}: {exc.strerror or exc}") from None


# ------------------------------------------------------------------------------------------------
# helpers
# ------------------------------------------------------------------------------------------------


def _label(motion: Motion) -> str:
    return motion.name or "motion"


def _floats(v: npt.ArrayLike) -> list[float]:
    """A JSON list of the values as float32 numbers would store them."""
    return [float(x) for x in np.asarray(v, dtype=np.float32).reshape(-1)]


def _prepared(motion: Motion, ground_root: bool) -> Motion:
    """Validate the motion and add the ground root when asked (:class:`ExportError` otherwise)."""
    if motion.num_frames == 0:
        raise ExportError(f"cannot export {_label(motion)}: it has no frames")
    if motion.num_joints > _MAX_SKIN_JOINTS - (1 if ground_root else 0):
        raise ExportError(f"cannot export {_label(motion)}: glTF skins here hold at most 65,536 joints")
    sk = motion.skeleton
    arrays = (motion.root_positions, motion.rotations, motion.joint_translations)
    if not all(np.all(np.isfinite(a)) for a in (*arrays, sk.offsets, sk.end_site_offsets)):
        raise ExportError(f"cannot export {_label(motion)}: it holds non-finite values (NaN or inf)")
    if not ground_root or sk.names[0] == GROUND_ROOT_NAME:
        return motion
    try:
        return add_ground_root(motion)
    except MotionError as exc:
        raise ExportError(f"cannot add a ground root to {_label(motion)}: {exc}") from None


def _rest_globals(parents: npt.NDArray[np.intp], offsets: Array) -> Array:
    """``(J, 3)`` global rest positions: offsets summed along the hierarchy (identity rotations)."""
    g = np.array(offsets, dtype=np.float64, copy=True)
    for j in range(1, len(parents)):
        g[j] += g[parents[j]]
    return g


def _bone_mesh(
    parents: npt.NDArray[np.intp],
    rest: Array,
    end_parents: npt.NDArray[np.intp],
    end_offsets: Array,
    grounded: bool,
) -> tuple[Array, Array, npt.NDArray[np.intp]] | None:
    """Flat-shaded octahedra along the rest-pose bones.

    Parameters
    ----------
    parents:
        ``(J,)`` parent joint indices.
    rest:
        ``(J, 3)`` global rest positions, metres.
    end_parents, end_offsets:
        ``(E,)`` joint and ``(E, 3)`` offset (metres) of each End Site.
    grounded:
        Joint 0 is the ground root: its links to its children are not drawn.

    Returns
    -------
    positions, normals:
        ``(V, 3)`` vertices (metres, rest pose) and unit face normals, ``V = 24 B`` for ``B``
        bones (8 triangles of 3 own vertices each, counter-clockwise seen from outside).
    joints:
        ``(V,)`` the joint each vertex is bound to (the bone's parent).
    ``None`` when there is no bone to draw.
    """
    child = np.arange(1, len(parents))
    par = parents[1:]
    if grounded:
        keep = par != 0
        child, par = child[keep], par[keep]
    head = np.concatenate((rest[par], rest[end_parents]))
    tail = np.concatenate((rest[child], rest[end_parents] + end_offsets))
    owner = np.concatenate((par, end_parents)).astype(np.intp)
    points = np.concatenate((rest, rest[end_parents] + end_offsets))
    body = float(np.max(points.max(axis=0) - points.min(axis=0)))
    vec = tail - head
    length = np.linalg.norm(vec, axis=-1)
    keep = length > _MIN_BONE_OF_BODY * body
    if body <= 0.0 or not np.any(keep):
        return None
    head, tail, owner, vec, length = head[keep], tail[keep], owner[keep], vec[keep], length[keep]

    d = vec / length[:, None]
    helper = np.eye(3)[np.argmin(np.abs(d), axis=1)]  # world axis least aligned with the bone
    u = np.cross(d, helper)
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    v = np.cross(d, u)
    half = 0.5 * np.minimum(BONE_WIDTH_OF_BODY * body, BONE_WIDTH_OF_LENGTH * length)[:, None]
    waist = head + BONE_WAIST * vec
    ring = waist[:, None] + half[:, None] * np.stack((u, v, -u, -v), axis=1)  # (B, 4, 3)
    nxt = np.roll(ring, -1, axis=1)
    apex = np.stack((np.repeat(head[:, None], 4, axis=1), np.repeat(tail[:, None], 4, axis=1)), axis=1)
    a = apex  # (B, 2, 4, 3): head fan, tail fan
    b = np.stack((nxt, ring), axis=1)
    c = np.stack((ring, nxt), axis=1)
    tri = np.stack((a, b, c), axis=-2).reshape(-1, 8, 3, 3)  # (B, 8 faces, 3 corners, xyz)
    n = np.cross(tri[:, :, 1] - tri[:, :, 0], tri[:, :, 2] - tri[:, :, 0])
    outward = np.sum(n * (tri.mean(axis=2) - waist[:, None]), axis=-1) >= 0  # waist is inside
    flipped = tri[:, :, [0, 2, 1]]
    tri = np.where(outward[..., None, None], tri, flipped)
    n = np.where(outward[..., None], n, -n)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    positions = tri.reshape(-1, 3)
    normals = np.repeat(n, 3, axis=1).reshape(-1, 3)
    joints = np.repeat(owner, 24)
    return positions, normals, joints


def _primitive(b: _Builder, positions: Array, normals: Array, joints: npt.NDArray[np.intp]) -> dict[str, Any]:
    """Write the vertex attributes and indices of the bone mesh; return the primitive JSON."""
    n = positions.shape[0]
    pos32 = positions.astype(np.float32)
    joint4 = np.zeros((n, 4), dtype=np.uint16)
    joint4[:, 0] = joints
    weight4 = np.zeros((n, 4), dtype=np.float32)
    weight4[:, 0] = 1.0
    index = np.arange(n, dtype=np.uint16 if n <= 65535 else np.uint32)
    attributes = {
        "POSITION": b.accessor(
            b.view(pos32, ARRAY_BUFFER), 0, FLOAT, n, "VEC3", pos32.min(axis=0), pos32.max(axis=0)
        ),
        "NORMAL": b.accessor(b.view(normals.astype(np.float32), ARRAY_BUFFER), 0, FLOAT, n, "VEC3"),
        "JOINTS_0": b.accessor(b.view(joint4, ARRAY_BUFFER), 0, UNSIGNED_SHORT, n, "VEC4"),
        "WEIGHTS_0": b.accessor(b.view(weight4, ARRAY_BUFFER), 0, FLOAT, n, "VEC4"),
    }
    index_type = UNSIGNED_SHORT if index.dtype == np.uint16 else UNSIGNED_INT
    indices = b.accessor(b.view(index, ELEMENT_ARRAY_BUFFER), 0, index_type, n, "SCALAR")
    return {"attributes": attributes, "indices": indices, "material": 0, "mode": 4}


class _Builder:
    """Accumulates the binary buffer, its buffer views and accessors."""

    def __init__(self) -> None:
        self.data = bytearray()
        self.views: list[dict[str, Any]] = []
        self.accessors: list[dict[str, Any]] = []

    def view(self, array: npt.NDArray[Any], target: int | None = None) -> int:
        """Append ``array`` (little-endian, C order) on a 4-byte boundary; return its view index."""
        self.data.extend(b"\0" * (-len(self.data) % 4))
        raw = np.ascontiguousarray(array, dtype=array.dtype.newbyteorder("<")).tobytes()
        view: dict[str, Any] = {"buffer": 0, "byteOffset": len(self.data), "byteLength": len(raw)}
        if target is not None:
            view["target"] = target
        self.data.extend(raw)
        self.data.extend(b"\0" * (-len(self.data) % 4))
        self.views.append(view)
        return len(self.views) - 1

    def accessor(
        self,
        view: int,
        offset: int,
        component: int,
        count: int,
        kind: str,
        lo: npt.ArrayLike | None = None,
        hi: npt.ArrayLike | None = None,
    ) -> int:
        """Add an accessor of ``count`` ``kind`` elements at byte ``offset`` (a multiple of 4)."""
        acc: dict[str, Any] = {
            "bufferView": view,
            "componentType": component,
            "count": count,
            "type": kind,
        }
        if offset:
            acc["byteOffset"] = offset
        if lo is not None and hi is not None:
            acc["min"] = _floats(lo)
            acc["max"] = _floats(hi)
        self.accessors.append(acc)
        return len(self.accessors) - 1


def _container(gltf: dict[str, Any], binary: bytes) -> bytes:
    """The GLB file: header, JSON chunk (space-padded), BIN chunk (zero-padded)."""
    text = json.dumps(gltf, ensure_ascii=False, separators=(",", ":"), allow_nan=False).encode("utf-8")
    text += b" " * (-len(text) % 4)
    binary += b"\0" * (-len(binary) % 4)
    total = 12 + 8 + len(text) + 8 + len(binary)
    if total >= 1 << 32:
        raise ExportError(f"the GLB file would be {total} bytes, over the 4 GiB limit of the format")
    return b"".join(
        (
            struct.pack("<4sII", GLB_MAGIC, GLB_VERSION, total),
            struct.pack("<II", len(text), CHUNK_JSON),
            text,
            struct.pack("<II", len(binary), CHUNK_BIN),
            binary,
        )
    )
