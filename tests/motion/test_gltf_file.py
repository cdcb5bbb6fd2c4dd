"""The one glTF reader (motion/gltf_file.py): skin trees in any node order, hostile hierarchies
refused at once (a cycle hung the character reader before), accessors bounded by their buffer."""

from __future__ import annotations

import struct
from typing import Any

import numpy as np
import pytest

from motion.errors import MotionError
from motion.gltf import parse_gltf
from motion.gltf_file import GltfFile
from motion.retarget.character import gltf_character
from tests.glb_writer import glb


def _doc(nodes: list[dict[str, Any]], joints: list[int]) -> dict[str, Any]:
    return {"asset": {"version": "2.0"}, "nodes": nodes, "skins": [{"joints": joints}]}


def test_a_skin_listed_children_first_is_ordered_parents_first() -> None:
    # node 0 hips (root) > node 1 spine > node 2 head; the skin lists them head, spine, hips;
    # node 3 a second leg under the hips, listed between
    nodes = [
        {"name": "hips", "children": [1, 3]},
        {"name": "spine", "translation": [0, 0.5, 0], "children": [2]},
        {"name": "head", "translation": [0, 0.4, 0]},
        {"name": "leg", "translation": [0.1, -0.5, 0]},
    ]
    order, parents = GltfFile(_doc(nodes, [2, 3, 1, 0]), b"", "t").skin_tree([2, 3, 1, 0])
    assert order == [0, 3, 1, 2]  # each joint after its parent, else in the skin's order
    assert parents == [-1, 0, 0, 2]
    char = gltf_character(glb(_doc(nodes, [2, 3, 1, 0])))
    assert char.skeleton.names == ("hips", "leg", "spine", "head")
    np.testing.assert_allclose(char.global_positions()[0][3], [0, 0.9, 0], atol=1e-9)


@pytest.mark.parametrize(
    ("nodes", "joints", "problem"),
    [
        # a joint under a loop of two non-joint nodes (the character reader looped for ever)
        ([{"name": "x", "children": [1, 2]}, {"name": "y", "children": [0]}, {"name": "j"}], [2], "cycle"),
        # two joints each the other's parent
        ([{"name": "a", "children": [1]}, {"name": "b", "children": [0]}], [0, 1], "cycle"),
        # two roots
        ([{"name": "a"}, {"name": "b"}], [0, 1], "several root joints"),
    ],
)
def test_hostile_hierarchies_are_refused_at_once(
    nodes: list[dict[str, Any]], joints: list[int], problem: str
) -> None:
    raw = glb(_doc(nodes, joints))
    with pytest.raises(MotionError, match=problem):
        gltf_character(raw)
    doc = _doc(nodes, joints)
    with pytest.raises(MotionError, match=problem):
        GltfFile(doc, b"", "t").skin_tree(joints)


def test_a_thousand_joint_chain_listed_backwards_is_ordered_quickly() -> None:
    # a chain of 3,000 joints, the skin listing it leaf first: the quadratic search of before
    # looked at ~4.5 million candidates; Kahn's algorithm looks at each joint once
    n = 3000
    nodes = [{"name": f"j{i}", "children": [i + 1]} for i in range(n - 1)] + [{"name": f"j{n - 1}"}]
    order, parents = GltfFile(_doc(nodes, []), b"", "t").skin_tree(list(range(n - 1, -1, -1)))
    assert order == list(range(n)) and parents == [-1, *range(n - 1)]


def test_an_accessor_past_its_buffer_is_refused() -> None:
    doc = {
        "asset": {"version": "2.0"},
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3"}],
        "bufferViews": [{"buffer": 0, "byteLength": 24}],
        "buffers": [{"byteLength": 24}],
    }
    f = GltfFile(doc, struct.pack("<6f", *range(6)), "bad.glb")
    with pytest.raises(MotionError, match=r"bad\.glb: accessor 0 reads past the end"):
        f.accessor(0)
    with pytest.raises(MotionError, match="bad.glb"):
        parse_gltf(b"glTF\x02\x00\x00\x00", source="bad.glb")
