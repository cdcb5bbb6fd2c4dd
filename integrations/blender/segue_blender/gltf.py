"""Reading GLB files in plain Python: the document, accessors, node transforms and animations;
and renaming nodes of a GLB (the bones of a character before it is uploaded).

Only what the add-on meets is read: a GLB container (JSON chunk, one binary chunk), float32
accessors and normalized integer ones (KHR_mesh_quantization's rotations), interleaved or not.
Times are seconds, lengths metres, glTF's axes (Y up, +Z forward), quaternions ``(x, y, z, w)``.
"""

from __future__ import annotations

import json
import struct
import sys
from array import array
from bisect import bisect_right
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from . import mat4

CHUNK_JSON = 0x4E4F534A
CHUNK_BIN = 0x004E4942

_COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}
_TYPES: dict[int, tuple[str, int, float]] = {  # componentType -> array code, bytes, normalization
    5126: ("f", 4, 1.0),
    5120: ("b", 1, 127.0),
    5121: ("B", 1, 255.0),
    5122: ("h", 2, 32767.0),
    5123: ("H", 2, 65535.0),
}


class GltfError(ValueError):
    """A file that is not a GLB the add-on can read, naming the problem."""


def split_glb(raw: bytes) -> tuple[dict[str, Any], bytes]:
    """The JSON document and the binary chunk (``b""`` when none) of a GLB container."""
    if len(raw) < 20 or raw[:4] != b"glTF":
        raise GltfError("not a GLB file (no 'glTF' header)")
    version, total = struct.unpack_from("<II", raw, 4)
    if version != 2:
        raise GltfError(f"GLB version {version}: only glTF 2.0 is read")
    length, kind = struct.unpack_from("<II", raw, 12)
    if kind != CHUNK_JSON:
        raise GltfError("the GLB's first chunk is not JSON")
    try:
        doc = json.loads(raw[20 : 20 + length])
    except ValueError as exc:
        raise GltfError(f"the GLB's JSON chunk does not parse: {exc}") from None
    if not isinstance(doc, dict):
        raise GltfError("the GLB's JSON is not an object")
    at = 20 + length
    binary = b""
    if len(raw) >= at + 8:
        blen, bkind = struct.unpack_from("<II", raw, at)
        if bkind == CHUNK_BIN:
            binary = raw[at + 8 : at + 8 + blen]
    return doc, binary


def join_glb(doc: Mapping[str, Any], binary: bytes) -> bytes:
    """A GLB container of ``doc`` and ``binary`` (each chunk padded to 4 bytes)."""
    text = json.dumps(doc, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    body = binary + b"\0" * (-len(binary) % 4)
    chunks = struct.pack("<II", len(text), CHUNK_JSON) + text
    if body:
        chunks += struct.pack("<II", len(body), CHUNK_BIN) + body
    return struct.pack("<III", 0x46546C67, 2, 12 + len(chunks)) + chunks


def rename_nodes(raw: bytes, names: Mapping[str, str]) -> bytes:
    """The GLB with nodes renamed (``old -> new``; others kept); the binary chunk is untouched.
    ``GltfError`` when two nodes would share a name."""
    doc, binary = split_glb(raw)
    taken: dict[str, int] = {}
    for i, node in enumerate(doc.get("nodes", [])):
        old = node.get("name")
        new = names.get(old, old) if isinstance(old, str) else old
        if isinstance(new, str):
            if new in taken:
                raise GltfError(f"renaming gives two nodes the name {new!r}")
            taken[new] = i
            node["name"] = new
    return join_glb(doc, binary)


def accessor(doc: Mapping[str, Any], binary: bytes, index: int) -> list[tuple[float, ...]]:
    """Accessor ``index`` as a list of tuples (one per element; normalized integers as floats)."""
    try:
        acc = doc["accessors"][index]
        count = int(acc["count"])
        width = _COMPONENTS[acc["type"]]
        code, size, norm = _TYPES[int(acc["componentType"])]
    except (KeyError, IndexError, TypeError, ValueError) as exc:
        raise GltfError(f"accessor {index}: unsupported or malformed ({exc})") from None
    if "bufferView" not in acc:
        return [(0.0,) * width] * count
    view = doc["bufferViews"][int(acc["bufferView"])]
    start = int(view.get("byteOffset", 0)) + int(acc.get("byteOffset", 0))
    stride = int(view.get("byteStride", 0)) or width * size
    end = start + stride * (count - 1) + width * size if count else start
    if end > len(binary):
        raise GltfError(f"accessor {index} reads past the binary chunk ({end} > {len(binary)} bytes)")
    if stride == width * size:
        flat = array(code)
        flat.frombytes(binary[start:end])
    else:
        flat = array(code)
        for k in range(count):
            at = start + k * stride
            flat.frombytes(binary[at : at + width * size])
    if sys.byteorder != "little" and size > 1:
        flat.byteswap()
    scale = norm if (code != "f" and acc.get("normalized")) else 1.0
    values = [v / scale for v in flat] if scale != 1.0 else list(map(float, flat))
    if code != "f" and scale != 1.0:
        values = [max(v, -1.0) for v in values]
    return [tuple(values[k * width : (k + 1) * width]) for k in range(count)]


@dataclass(frozen=True, slots=True)
class Node:
    """A node: its name, rest translation, rotation ``(x, y, z, w)`` and scale, parent and children."""

    name: str
    translation: mat4.Vec3
    rotation: mat4.Quat
    scale: mat4.Vec3
    parent: int | None
    children: tuple[int, ...]

    def matrix(self) -> mat4.Mat4:
        """The node's rest local matrix."""
        return mat4.from_trs(self.translation, self.rotation, self.scale)


def nodes_of(doc: Mapping[str, Any]) -> list[Node]:
    """Every node with its rest transform (a ``matrix`` split into TRS) and parent."""
    raw = doc.get("nodes", [])
    parent: dict[int, int] = {}
    for i, nd in enumerate(raw):
        for c in nd.get("children", []):
            parent[int(c)] = i
    out = []
    for i, nd in enumerate(raw):
        if "matrix" in nd:
            m = mat4.from_column_major(nd["matrix"])
            t, q, s = mat4.translation(m), mat4.rotation_of(m), mat4.scale_of(m)
        else:
            t = _vec3(nd.get("translation", (0.0, 0.0, 0.0)))
            r = nd.get("rotation", (0.0, 0.0, 0.0, 1.0))
            q = (float(r[0]), float(r[1]), float(r[2]), float(r[3]))
            s = _vec3(nd.get("scale", (1.0, 1.0, 1.0)))
        name = nd.get("name")
        out.append(
            Node(
                name if isinstance(name, str) else f"node{i}",
                t,
                q,
                s,
                parent.get(i),
                tuple(int(c) for c in nd.get("children", [])),
            )
        )
    return out


def _vec3(v: Any) -> mat4.Vec3:
    return (float(v[0]), float(v[1]), float(v[2]))


def rest_world(nodes: list[Node]) -> list[mat4.Mat4]:
    """Each node's rest matrix in the scene (its parents' transforms applied)."""
    out: list[mat4.Mat4 | None] = [None] * len(nodes)

    def world(i: int) -> mat4.Mat4:
        m = out[i]
        if m is None:
            p = nodes[i].parent
            m = nodes[i].matrix() if p is None else mat4.mul(world(p), nodes[i].matrix())
            out[i] = m
        return m

    return [world(i) for i in range(len(nodes))]


def skin_joints(doc: Mapping[str, Any], skin: int = 0) -> list[int]:
    """The node indices of a skin's joints (``GltfError`` when the file has no such skin)."""
    skins = doc.get("skins", [])
    if skin >= len(skins) or not skins[skin].get("joints"):
        raise GltfError("the file has no skin with joints")
    return [int(j) for j in skins[skin]["joints"]]


@dataclass(slots=True)
class Track:
    """One node's animated values at ``times`` (seconds): translations or rotations, one tuple a
    time (a constant channel has one)."""

    times: list[float]
    values: list[tuple[float, ...]]

    def at(self, t: float, rotation: bool = False) -> tuple[float, ...]:
        """The value at time ``t`` (seconds): a key's own value at its time, linear in between
        (normalized for a ``rotation``, the shorter way), held before the first key and after the
        last (a constant channel has one key)."""
        times, values = self.times, self.values
        if len(values) == 1 or t <= times[0]:
            return values[0]
        if t >= times[-1]:
            return values[-1]
        k = bisect_right(times, t) - 1
        t0, t1 = times[k], times[k + 1]
        u = (t - t0) / (t1 - t0) if t1 > t0 else 0.0
        a, b = values[k], values[k + 1]
        if u <= 1e-9:
            return a
        if rotation and sum(x * y for x, y in zip(a, b, strict=True)) < 0:
            b = tuple(-x for x in b)
        out = tuple(x + (y - x) * u for x, y in zip(a, b, strict=True))
        if rotation:
            n = sum(x * x for x in out) ** 0.5 or 1.0
            out = tuple(x / n for x in out)
        return out


@dataclass(slots=True)
class Animation:
    """An animation's channels: node index -> ``{"translation" | "rotation" | "scale": Track}``,
    and the times (seconds) of its keys: those of its channel with the most keys (Segue writes one
    key per frame on every channel that moves, one key on those that do not)."""

    name: str
    channels: dict[int, dict[str, Track]] = field(default_factory=dict)
    times: list[float] = field(default_factory=list)


def animation(doc: Mapping[str, Any], binary: bytes, index: int = -1) -> Animation:
    """Animation ``index`` (default: the last one, the one Segue adds) of a GLB document."""
    anims = doc.get("animations", [])
    if not anims:
        raise GltfError("the file has no animation")
    a = anims[index]
    out = Animation(str(a.get("name", "")))
    samplers = a.get("samplers", [])
    cache: dict[int, list[tuple[float, ...]]] = {}

    def read(i: int) -> list[tuple[float, ...]]:
        if i not in cache:
            cache[i] = accessor(doc, binary, i)
        return cache[i]

    longest: list[float] = []
    for ch in a.get("channels", []):
        target = ch.get("target", {})
        if "node" not in target or target.get("path") not in ("translation", "rotation", "scale"):
            continue
        sampler = samplers[int(ch["sampler"])]
        if sampler.get("interpolation", "LINEAR") == "CUBICSPLINE":
            raise GltfError("CUBICSPLINE animation channels are not read (Segue writes LINEAR ones)")
        times = [t[0] for t in read(int(sampler["input"]))]
        values = read(int(sampler["output"]))
        out.channels.setdefault(int(target["node"]), {})[str(target["path"])] = Track(times, values)
        if len(times) > len(longest):
            longest = times
    out.times = longest
    return out
