"""A glTF 2.0 file read once: its JSON document, its one binary buffer, accessor values and node
transforms.

The one reader behind every glTF input of Segue: animations as motions (:mod:`motion.gltf`), a
character's skeleton in its bind pose (:mod:`motion.retarget.character`) and its skinned mesh
(:mod:`motion.skinning`). Buffers (GLB binary chunk, ``data:`` URIs, files beside a ``.gltf``) are
joined by :func:`motion.export.gltf_doc.read_gltf`, which the binder also uses to write a user's
file back; :meth:`GltfFile.json_only` reads the JSON chunk alone, for what needs no buffer (a
skeleton's bind pose, an animation's key count and span).

Hand-written rather than ``pygltflib``: what Segue needs of a file is accessor arrays and node
transforms as numpy, with errors that name the file and the part that is wrong; the library would
add a dataclass layer over the same JSON and still leave the strided reads and transforms to us.

Units are the file's: metres, Y up, as glTF says; node rotations are quaternions ``(x, y, z, w)``.
"""

from __future__ import annotations

import heapq
import json
import struct
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from . import rotations as rot
from .errors import ExportError, GltfError, MotionError

Array = npt.NDArray[np.float64]

_COMPONENTS = {
    5120: np.int8,
    5121: np.uint8,
    5122: np.int16,
    5123: np.uint16,
    5125: np.uint32,
    5126: np.float32,
}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_NORMALIZED = {5120: 127.0, 5121: 255.0, 5122: 32767.0, 5123: 65535.0}
_CHUNK_JSON = 0x4E4F534A


def gltf_json(raw: bytes) -> dict[str, Any]:
    """The JSON document of a GLB container or a ``.gltf`` text, without reading its buffers
    (:class:`GltfError` when it is not glTF)."""
    try:
        if raw[:4] == b"glTF":
            if len(raw) < 20:
                raise GltfError("truncated GLB header")
            length, kind = struct.unpack_from("<II", raw, 12)
            if kind != _CHUNK_JSON:
                raise GltfError("the GLB's first chunk is not JSON")
            doc = json.loads(raw[20 : 20 + length])
        else:
            doc = json.loads(raw)
    except (ValueError, struct.error) as exc:
        raise GltfError(f"not a glTF/GLB file: {exc}") from None
    if not isinstance(doc, dict):
        raise GltfError("not a glTF document (its JSON is not an object)")
    return doc


class GltfFile:
    """A glTF document (``doc``) and its one binary buffer, with accessor reads and the node
    hierarchy (``nodes``; ``parent[i]``, the parent node of node ``i``, absent for roots).

    Errors are :class:`MotionError` prefixed with ``source`` (the file's name for the user)."""

    def __init__(self, doc: dict[str, Any], buffer: bytes | bytearray, source: str) -> None:
        self.doc = doc
        self.buffer = bytes(buffer)
        self.source = source
        try:
            self.nodes: list[dict[str, Any]] = list(doc.get("nodes") or [])
            self.parent: dict[int, int] = {
                int(c): i for i, node in enumerate(self.nodes) for c in node.get("children") or []
            }
        except (TypeError, ValueError, AttributeError) as exc:
            raise self.error(f"malformed node hierarchy: {exc}") from None

    @classmethod
    def read(cls, raw: bytes, base_dir: str | Path | None = None, source: str = "glTF file") -> GltfFile:
        """The whole file: document and buffers (``base_dir``: where a ``.gltf`` file's buffer
        files are)."""
        from .export.gltf_doc import read_gltf

        try:
            doc, buffer = read_gltf(raw, base_dir)
        except (ExportError, MotionError) as exc:
            raise GltfError(f"{source}: {exc}") from None
        return cls(doc, buffer, source)

    @classmethod
    def json_only(cls, raw: bytes, source: str = "glTF file") -> GltfFile:
        """The document alone (no buffer: :meth:`accessor` refuses); node transforms and accessor
        metadata are there."""
        try:
            doc = gltf_json(raw)
        except MotionError as exc:
            raise GltfError(f"{source}: {exc}") from None
        return cls(doc, b"", source)

    def error(self, problem: str) -> GltfError:
        return GltfError(f"{self.source}: {problem}")

    def accessor(self, index: int) -> Array:
        """Accessor ``index`` as ``(count, width)`` float64: normalised integers scaled to [0, 1]
        or [-1, 1], plain integers as they are; sparse accessors and non-finite values refused."""
        try:
            acc = self.doc["accessors"][int(index)]
            if "sparse" in acc:
                raise self.error(f"accessor {index} is sparse, which Segue does not read; re-export the file")
            dtype = np.dtype(_COMPONENTS[int(acc["componentType"])]).newbyteorder("<")
            width = _WIDTH[str(acc["type"])]
            count = int(acc["count"])
            if "bufferView" not in acc:
                return np.zeros((count, width))
            view = self.doc["bufferViews"][int(acc["bufferView"])]
            start = int(view.get("byteOffset", 0)) + int(acc.get("byteOffset", 0))
            item = dtype.itemsize * width
            stride = int(view.get("byteStride", 0)) or item
            if count < 0 or start < 0 or (count and start + stride * (count - 1) + item > len(self.buffer)):
                raise self.error(f"accessor {index} reads past the end of its buffer")
            raw = np.ndarray(
                shape=(count, width),
                dtype=dtype,
                buffer=self.buffer,
                offset=start,
                strides=(stride, dtype.itemsize),
            )
        except MotionError:
            raise
        except (IndexError, KeyError, TypeError, ValueError) as exc:
            raise self.error(f"malformed accessor {index}: {exc}") from None
        out = raw.astype(np.float64)
        if acc.get("normalized") and int(acc["componentType"]) in _NORMALIZED:
            out = np.maximum(out / _NORMALIZED[int(acc["componentType"])], -1.0)
        if not np.all(np.isfinite(out)):
            raise self.error(f"accessor {index} holds values that are not finite")
        return out

    def local(self, i: int) -> tuple[Array, Array, Array]:
        """Node ``i``'s own translation ``(3,)``, rotation ``(4,)`` (x, y, z, w, unit) and scale
        ``(3,)``, from its ``matrix`` or its TRS."""
        node = self.nodes[i]
        try:
            if "matrix" in node:
                m = np.array(node["matrix"], dtype=np.float64).reshape(4, 4).T
                scale = np.linalg.norm(m[:3, :3], axis=0)
                if np.any(scale <= 0) or np.linalg.det(m[:3, :3]) < 0:
                    name = node.get("name", "")
                    raise self.error(f"node {i} ({name!r}) has a degenerate or mirroring matrix")
                q = rot.from_matrix(m[:3, :3] / scale)
                return m[:3, 3].copy(), np.asarray(q, dtype=np.float64), scale
            t = np.array(node.get("translation", [0.0, 0.0, 0.0]), dtype=np.float64)
            q = np.array(node.get("rotation", [0.0, 0.0, 0.0, 1.0]), dtype=np.float64)
            s = np.array(node.get("scale", [1.0, 1.0, 1.0]), dtype=np.float64)
        except MotionError:
            raise
        except (TypeError, ValueError) as exc:
            raise self.error(f"node {i} has a malformed transform: {exc}") from None
        if not (t.shape == (3,) and q.shape == (4,) and s.shape == (3,)):
            raise self.error(f"node {i} has a malformed translation, rotation or scale")
        norm = float(np.linalg.norm(q))
        if not norm > 0:
            raise self.error(f"node {i} has a zero rotation quaternion")
        return t, q / norm, s

    def local_matrix(self, i: int) -> Array:
        """Node ``i``'s ``(4, 4)`` local transform (column vectors)."""
        t, q, s = self.local(i)
        m = np.eye(4)
        m[:3, :3] = rot.to_matrix(q) * s
        m[:3, 3] = t
        return m

    def world_matrices(self, nodes: Iterable[int] | None = None) -> dict[int, Array]:
        """The ``(4, 4)`` rest world transform (its parents' applied) of each of ``nodes``
        (every node when None), by node index; only those nodes and their ancestors are read."""
        world: dict[int, Array] = {}

        def of(i: int) -> Array:
            if i not in world:
                m = self.local_matrix(i)
                world[i] = of(self.parent[i]) @ m if i in self.parent else m
            return world[i]

        try:
            wanted = range(len(self.nodes)) if nodes is None else nodes
            return {int(i): of(int(i)) for i in wanted}
        except RecursionError:
            raise self.error("the node hierarchy has a cycle") from None

    def skin_tree(self, joints: Sequence[int]) -> tuple[list[int], list[int]]:
        """A skin's ``joints`` (node indices), each after its parent joint, and each one's parent
        in that order (``-1`` for the root). The order is the skin's own where it already puts
        parents first (any glTF exporter's), else the first joint in skin order whose parent is
        placed (Kahn's algorithm on skin positions: O(J log J)). A joint's parent is its nearest
        ancestor node in the skin. Raises for a cycle or for joints that form several trees."""
        unique = list(dict.fromkeys(int(j) for j in joints))
        at = {node: k for k, node in enumerate(unique)}
        up: dict[int, int | None] = {}
        for node in unique:
            p = self.parent.get(node)
            for _ in range(len(self.nodes) + 1):  # every node above it at most: a cycle ends here
                if p is None or p in at:
                    break
                p = self.parent.get(p)
            else:
                raise self.error("the node hierarchy has a cycle")
            up[node] = p
        children: dict[int, list[int]] = {}
        for node in unique:
            if up[node] is not None:
                children.setdefault(int(up[node]), []).append(node)  # type: ignore[arg-type]
        ready = [at[n] for n in unique if up[n] is None]
        heapq.heapify(ready)
        order: list[int] = []
        while ready:
            node = unique[heapq.heappop(ready)]
            order.append(node)
            for c in children.get(node, []):
                heapq.heappush(ready, at[c])
        if len(order) != len(unique):
            raise self.error("the skin's joint hierarchy has a cycle")
        index = {node: k for k, node in enumerate(order)}
        parents = [-1 if up[n] is None else index[int(up[n])] for n in order]  # type: ignore[arg-type]
        if sum(p < 0 for p in parents) != 1:
            raise self.error("the skin's joints do not form one tree (several root joints)")
        return order, parents

    def name(self, i: int) -> str:
        """Node ``i``'s name (``joint<i>`` when it has none)."""
        return str(self.nodes[i].get("name") or f"joint{i}")
