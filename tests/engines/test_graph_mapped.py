"""A graph engine loaded from memory-mapped database files keeps the stored arrays as they are:
its edge tree, root tracks, contacts and motion library are read-only views of the mapped pages
(int32 / float32 as stored, widened where they are computed with), not private widened copies,
and it finds the same solutions, bit for bit, as an engine over arrays widened at load."""

from __future__ import annotations

import dataclasses
import mmap
import pickle
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from engines import container
from engines.base import foot_floor_arrays
from engines.graph.engine import GraphEngine
from engines.library import MotionLibrary, StoredMotion, library_from_arrays, library_to_arrays
from engines.registry import parse_database_spec
from motion import Motion, MotionError
from schemas.graph import GraphRequest
from tests.engines.emitters import Collect

from .graph_synthetic import synthetic_library
from .test_graph_search import _with_reference_root

EDGE_FIELDS = ("from_clip", "from_frame", "to_clip", "to_frame", "cost", "parent", "left", "right")


def built_arrays() -> tuple[dict[str, Any], MotionLibrary]:
    """A graph database's arrays (as a worker stores them) of synthetic walks on a Bandai-style
    skeleton: a static ``joint_Root`` with the hips as its translated child (animated joint
    translations), joint 0 moving in clip 1 (assembly pins it)."""
    lib = _with_reference_root(synthetic_library(300), moving=1)
    spec = parse_database_spec({"kind": "graph", "clips": [{"bvh": "x.bvh"}]})
    arrays: dict[str, Any] = library_to_arrays(lib)
    arrays.update(GraphEngine.build(spec, lib, Collect(), lambda: False))
    arrays.update(GraphEngine.quality_reference_of(lib, arrays).to_arrays())
    arrays.update(foot_floor_arrays(lib, GraphEngine.example_clips(lib, arrays)))
    return arrays, lib


@pytest.fixture(scope="module")
def database(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict[str, Any], Path]:
    arrays, _ = built_arrays()
    root = tmp_path_factory.mktemp("graphdb")
    container.write_dir(root, arrays)
    return arrays, root


def mapped(root: Path, monkeypatch: pytest.MonkeyPatch) -> dict[str, Any]:
    """Every array of the database memory-mapped (however small), as a worker maps big ones."""
    monkeypatch.setattr(container, "MMAP_MIN_BYTES", 0)
    return container.load_all(root)


def on_a_map(a: np.ndarray) -> bool:
    """Whether ``a``'s memory belongs to a memory map (its base chain ends in an ``mmap``)."""
    base: Any = a
    while isinstance(base, np.ndarray):
        base = base.base
    return isinstance(base, mmap.mmap)


def view_of(a: np.ndarray, stored: np.ndarray) -> bool:
    return bool(np.shares_memory(a, stored)) and on_a_map(a) and not a.flags.writeable


def test_a_loaded_engine_keeps_views_of_the_mapped_arrays(
    database: tuple[dict[str, Any], Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    arrays, root = database
    stored = mapped(root, monkeypatch)
    engine = GraphEngine.load(stored)
    assert isinstance(engine, GraphEngine)
    for f in EDGE_FIELDS:
        a = getattr(engine.tree, f)
        assert view_of(a, stored[f"graph.edges.{f}"]), f
        assert a.dtype == (np.float32 if f == "cost" else np.int32)
    assert engine.tree.size > 100
    for f in ("root_xz", "root_yaw"):
        assert view_of(getattr(engine.tracks, f), stored[f"graph.tracks.{f}"]), f
    assert view_of(engine.contacts.flags, stored["graph.contacts.flags"])
    assert engine.contacts.flags.shape[1] > 0
    rotations, translations = stored["library.rotations"], stored["library.joint_translations"]
    assert rotations.dtype == translations.dtype == np.float32 and translations.shape[1] == 1
    for m in engine.library.motions:
        assert isinstance(m, StoredMotion)
        q, jt = m.stored_arrays
        assert view_of(q, rotations) and view_of(jt, translations)
        assert view_of(m.root_positions, stored["library.root_positions"])
    # widened where read: float64, the stored numbers
    m = engine.library.motions[2]
    assert m.rotations.dtype == m.joint_translations.dtype == np.float64
    np.testing.assert_array_equal(m.rotations, m.stored_arrays[0].astype(np.float64))


def widened(arrays: dict[str, Any]) -> dict[str, Any]:
    """The arrays as the engine held them before it kept the stored ones: int64 edge indices,
    float64 costs and motion."""
    out = dict(arrays)
    for f in EDGE_FIELDS:
        out[f"graph.edges.{f}"] = arrays[f"graph.edges.{f}"].astype(np.float64 if f == "cost" else np.int64)
    for k in ("library.rotations", "library.joint_translations"):
        out[k] = arrays[k].astype(np.float64)
    return out


REQUESTS: list[dict[str, Any]] = [
    {
        "engine": "graph",
        "frames": 200,
        "seed": 3,
        "alternatives": 2,
        "constraints": [
            {"type": "body", "frame": 0, "position": [0.0, 0.0], "heading_deg": 0.0},
            {"type": "body", "frame": 199, "position": [2.0, 5.0], "heading_deg": 60.0},
            {"type": "obstacle", "disc": {"center": [0.5, 2.5], "radius": 0.4}},
        ],
    },
    {
        "engine": "graph",
        "frames": 150,
        "seed": 8,
        "constraints": [
            {"type": "body", "frame": 0, "position": [0.0, 0.0], "heading_deg": 0.0},
            {"type": "joint", "frame": 80, "joint": "lHand", "position": [0.3, 1.1, 2.0]},
            {"type": "pose", "frame": 120, "clip": "left", "clip_frame": 40},
            {"type": "label", "label": "slow", "start": 0, "end": 60},
        ],
    },
]


@pytest.mark.parametrize("body", REQUESTS, ids=["goal-obstacle", "joint-pose-label"])
def test_mapped_and_widened_engines_find_the_same_solutions(
    database: tuple[dict[str, Any], Path], monkeypatch: pytest.MonkeyPatch, body: dict[str, Any]
) -> None:
    arrays, root = database
    request = GraphRequest.model_validate(body)
    runs = []
    for source in (mapped(root, monkeypatch), widened(arrays)):
        engine = GraphEngine.load(source)
        assert isinstance(engine, GraphEngine)
        out = Collect()
        engine.searcher(request.seed).run(request, 600.0, out, lambda: False, max_rounds=3)
        runs.append(out.solutions)
    a, b = runs
    assert len(a) == len(b) >= 2
    assert isinstance(GraphEngine.load(widened(arrays)).library.motions[0], Motion)
    for s, t in zip(a, b, strict=True):
        assert s.score == t.score and s.terms == t.terms and s.provenance == t.provenance
        for f in ("root_positions", "rotations", "joint_translations"):
            x, y = getattr(s.motion, f), getattr(t.motion, f)
            assert x.dtype == y.dtype == np.float64 and x.tobytes() == y.tobytes(), f


def test_stored_motion_reads_as_the_widened_motion() -> None:
    arrays, lib = built_arrays()
    stored = library_from_arrays(arrays)
    wide = library_from_arrays(widened(arrays))
    s, w = stored.motions[1], wide.motions[1]
    assert isinstance(s, StoredMotion) and type(w) is Motion
    for f in ("root_positions", "rotations", "joint_translations"):
        assert getattr(s, f).tobytes() == getattr(w, f).tobytes()
    assert s.slice(10, 20).rotations.tobytes() == w.slice(10, 20).rotations.tobytes()
    assert s.global_positions().tobytes() == w.global_positions().tobytes()
    moved = dataclasses.replace(s, name="moved")
    assert moved.name == "moved" and moved.rotations.tobytes() == w.rotations.tobytes()
    back = pickle.loads(pickle.dumps(s))
    assert back.joint_translations.tobytes() == w.joint_translations.tobytes()
    with pytest.raises(MotionError, match="disagree with the skeleton"):
        StoredMotion(s.skeleton, s.root_positions[:5], s.stored_arrays[0], s.fps, s.stored_arrays[1])
    with pytest.raises(MotionError, match="fps"):
        StoredMotion(s.skeleton, s.root_positions, *s.stored_arrays[:1], 0.0, s.stored_arrays[1])
    assert lib.motions[1].rotations.shape == s.rotations.shape


def test_edge_transforms_by_blocks_are_those_computed_at_once(
    database: tuple[dict[str, Any], Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The index computes its edge transforms a block of edges at a time (small temporaries at
    load): the same bits as one block of every edge."""
    from engines.graph import paths
    from engines.graph.model import EdgeTree, RootTracks

    arrays, _ = database
    tree, tracks = EdgeTree.from_arrays(arrays), RootTracks.from_arrays(arrays)
    whole = paths.GraphIndex(tree, tracks)
    monkeypatch.setattr(paths, "EDGE_BLOCK", 7)
    blocks = paths.GraphIndex(tree, tracks)
    assert tree.size > 10 * 7
    for f in ("pad_theta", "pad_turn", "pad_shift"):
        a, b = getattr(whole, f), getattr(blocks, f)
        assert a.shape == (tree.size + 1,) and a.tobytes() == b.tobytes(), f
    assert whole.pad_theta[-1] == 0.0 and whole.pad_shift[-1] == 0.0 and whole.pad_turn[-1] == 1.0
