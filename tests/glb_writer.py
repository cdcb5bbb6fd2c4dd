"""A small glTF writer of the tests' own (not Segue's exporter, so the characters the tests build
are not made by the code under test): the GLB container, and an armature's nodes from its rest.

Units: whatever the caller's world matrices hold (metres, or centimetres under an ``Armature``
node scaled 0.01 as DCC exports write).
"""

from __future__ import annotations

import json
import struct
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from motion import rotations as rot

Array = npt.NDArray[np.float64]
JSON_CHUNK = 0x4E4F534A
BIN_CHUNK = 0x004E4942


def glb(doc: dict[str, Any], binary: bytes | bytearray = b"") -> bytes:
    """A GLB container of ``doc`` (JSON padded with spaces) and ``binary`` (padded with zeros;
    no BIN chunk when empty)."""
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    data = bytes(binary) + b"\0" * (-len(binary) % 4)
    chunks = [struct.pack("<II", len(text), JSON_CHUNK), text]
    if data:
        chunks += [struct.pack("<II", len(data), BIN_CHUNK), data]
    total = 12 + sum(len(c) for c in chunks)
    return b"".join([struct.pack("<4sII", b"glTF", 2, total), *chunks])


def read_glb(raw: bytes) -> tuple[dict[str, Any], bytes]:
    """The document and binary chunk of a GLB (``b""`` when it has none)."""
    n = struct.unpack_from("<I", raw, 12)[0]
    doc = json.loads(raw[20 : 20 + n])
    at = 20 + n
    binary = raw[at + 8 : at + 8 + struct.unpack_from("<I", raw, at)[0]] if len(raw) > at + 8 else b""
    return doc, binary


def armature_nodes(
    world: Array,
    rotations: Array,
    names: Sequence[str],
    parents: Sequence[int],
    armature_scale: float,
    mesh_name: str,
) -> list[dict[str, Any]]:
    """Nodes of an ``Armature`` (node 0, scaled ``armature_scale``), its joints (nodes 1..J, in
    ``names`` order, each a child of its parent joint) and a skinned mesh node ``mesh_name``
    (mesh 0, skin 0), from the joints' rest ``world`` matrices ``(J, 4, 4)`` (the armature's
    scale in them) and world ``rotations`` ``(J, 4)``."""
    arm = np.diag([armature_scale, armature_scale, armature_scale, 1.0])
    nodes: list[dict[str, Any]] = [{"name": "Armature", "scale": [armature_scale] * 3, "children": [1]}]
    for k, name in enumerate(names):
        parent = world[parents[k]] if parents[k] >= 0 else arm
        local = np.linalg.inv(parent) @ world[k]
        q = rotations[k] if parents[k] < 0 else rot.multiply(rot.inverse(rotations[parents[k]]), rotations[k])
        node: dict[str, Any] = {
            "name": name,
            "translation": [float(x) for x in local[:3, 3]],
            "rotation": [float(x) for x in rot.normalize(q)],
        }
        kids = [c + 1 for c, p in enumerate(parents) if p == k]
        if kids:
            node["children"] = kids
        nodes.append(node)
    nodes.append({"name": mesh_name, "mesh": 0, "skin": 0})
    return nodes
