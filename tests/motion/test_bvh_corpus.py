"""The BVH reader on real files that nobody here wrote, each with the warnings it must give.

The corpus (``tests/data/bvh-corpus/README.md`` says where each file comes from and under which
licence): assimp's test models (vendored, gzip of the original bytes) and the test files of two
BVH packages on PyPI, read from their sdists, which ``tests/run.sh`` downloads (pinned, once) into
``$SEGUE_BVH_CORPUS_DIR`` (default ``~/.cache/segue/bvh-corpus``); without them those cases skip,
except in CI (``CI=true``), where they fail. Then the same files with the quirks real exporters
write and these files happen not to have (decimal commas, missing End Sites, a short frame count),
made from them by plain text edits.
"""

from __future__ import annotations

import gzip
import os
import re
import tarfile
from pathlib import Path

import numpy as np
import pytest

from motion import BvhError, parse_bvh
from motion.errors import ReadWarning

DATA = Path(__file__).resolve().parents[1] / "data" / "bvh-corpus"
SDISTS = {"bvhtoolbox": "bvhtoolbox-0.1.3.tar.gz", "bvhtools": "bvhtools-1.6.0.tar.gz"}
"""PyPI sdists holding test BVH files (keep in step with tests/run.sh)."""


def corpus_dir() -> Path:
    default = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "segue" / "bvh-corpus"
    return Path(os.environ.get("SEGUE_BVH_CORPUS_DIR") or default)


def corpus_bytes(ref: str) -> bytes:
    """The bytes of a corpus file: ``NAME`` in tests/data/bvh-corpus, or ``PACKAGE:MEMBER`` of a
    downloaded sdist."""
    if ":" not in ref:
        return gzip.decompress((DATA / ref).read_bytes())
    package, member = ref.split(":", 1)
    sdist = corpus_dir() / SDISTS[package]
    if not sdist.is_file():
        message = f"{sdist} is missing (tests/run.sh downloads it)"
        if os.environ.get("CI") == "true":
            pytest.fail(f"the PyPI corpus is required in CI: {message}")
        pytest.skip(message)
    with tarfile.open(sdist) as tar:
        fh = tar.extractfile(member)
        assert fh is not None, f"{member} is not a file of {sdist}"
        return fh.read()


# (file, frames, joints, fps, [(warning code, line)])
CORPUS: list[tuple[str, int, int, float, list[tuple[str, int]]]] = [
    # a boxing capture declaring one frame fewer than it holds (the refused file), with
    # trailing spaces on every line and a tab-indented hierarchy
    ("Boxing_Toes.bvh.gz", 3070, 21, 100.0, [("frame_count", 128)]),
    # cgspeed's CMU conversion: ".0083333" frame time without a leading zero
    ("01_01.bvh.gz", 2752, 31, 120.0, []),
    # Mixamo rig names with colons, CRLF, tabs between OFFSET numbers
    ("bvhtoolbox:bvhtoolbox-0.1.3/tests/example_files/test_freebvh.bvh", 69, 55, 30.0, []),
    # CRLF, a tab after "Frames:" and "Frame Time:", two-space indents
    ("bvhtoolbox:bvhtoolbox-0.1.3/tests/example_files/test_mocapbank.bvh", 455, 19, 30.0, []),
    # CRLF, a space after the last channel name
    ("bvhtools:bvhtools-1.6.0/testBvhFiles/test.bvh", 7184, 22, 30.0, []),
    ("bvhtools:bvhtools-1.6.0/testBvhFiles/test2.bvh", 3945, 22, 30.0, []),
    # Blender's exporter: six channels on every joint, dotted names (spine.001)
    ("bvhtools:bvhtools-1.6.0/testBvhFiles/test3.bvh", 3089, 19, 24.0, []),
]


def read(data: bytes, source: str = "<bytes>") -> tuple[object, list[ReadWarning]]:
    notes: list[ReadWarning] = []
    return parse_bvh(data, source=source, warnings=notes), notes


@pytest.mark.parametrize(("ref", "frames", "joints", "fps", "expected"), CORPUS, ids=[c[0] for c in CORPUS])
def test_real_files_read_with_their_warnings(
    ref: str, frames: int, joints: int, fps: float, expected: list[tuple[str, int]]
) -> None:
    data = corpus_bytes(ref)
    m, notes = read(data, ref)
    assert (m.num_frames, m.num_joints, round(m.fps, 3)) == (frames, joints, fps)  # type: ignore[attr-defined]
    assert [(w.code, w.line) for w in notes] == expected, [str(w) for w in notes]
    assert all(w.source == ref for w in notes)
    height = m.to_units("m").global_positions()[..., 1]  # type: ignore[attr-defined]
    standing = float(np.median(height.max(axis=1) - height.min(axis=1)))
    assert 1.0 < standing < 2.2, f"{ref} reads as a {standing:.2f} m body in {m.units}"  # type: ignore[attr-defined]


def test_the_frame_count_warning_reads_exactly_the_lines_present() -> None:
    data = corpus_bytes("Boxing_Toes.bvh.gz")
    m, notes = read(data)
    assert str(notes[0]) == (
        "<bytes>:128: Frames: 3069, but the file holds 3070 frame lines: read 3070 (the lines present win)"
    )
    fixed, none = read(data.replace(b"Frames:    3069", b"Frames:    3070"))
    assert none == []
    np.testing.assert_array_equal(m.rotations, fixed.rotations)  # type: ignore[attr-defined]
    np.testing.assert_array_equal(m.root_positions, fixed.root_positions)  # type: ignore[attr-defined]
    fewer, _ = read(data.replace(b"Frames:    3069", b"Frames:    9000"))  # off by thousands: the same
    np.testing.assert_array_equal(m.rotations, fewer.rotations)  # type: ignore[attr-defined]


def _cmu() -> bytes:
    return corpus_bytes("01_01.bvh.gz")


def test_decimal_commas_read_as_points() -> None:
    data = _cmu()
    head, _, rows = data.partition(b"MOTION")
    comma = head.replace(b".", b",") + b"MOTION" + rows.replace(b".", b",")
    m, notes = read(comma)
    plain, _ = read(data)
    assert [(w.code, w.line) for w in notes] == [
        ("decimal_comma", 4),
        ("decimal_comma", 187),
        ("decimal_comma", 188),
    ]
    np.testing.assert_array_equal(m.rotations, plain.rotations)  # type: ignore[attr-defined]
    np.testing.assert_array_equal(m.skeleton.offsets, plain.skeleton.offsets)  # type: ignore[attr-defined]


def test_commas_beside_points_are_an_error_naming_the_line() -> None:
    data = _cmu()
    lines = data.split(b"\n")
    lines[200] = lines[200].replace(b".", b",", 1)  # one number of one frame line
    with pytest.raises(BvhError, match="not a number.*decimal commas beside decimal points") as info:
        parse_bvh(b"\n".join(lines))
    assert info.value.line == 201


def test_missing_end_sites_read_with_a_warning() -> None:
    text = _cmu().decode()
    bare = re.sub(r"\n\s*End Site\s*\{\s*OFFSET[^\n]*\n\s*\}", "", text)
    assert bare.count("End Site") == 0
    m, notes = read(bare.encode())
    assert [w.code for w in notes] == ["missing_end_site"]
    assert "7 leaf joints without an End Site" in notes[0].problem
    assert m.skeleton.end_site_parents.size == 0  # type: ignore[attr-defined]
    plain, _ = read(text.encode())
    np.testing.assert_allclose(m.global_positions(), plain.global_positions())  # type: ignore[attr-defined]


def test_a_short_frame_count_reads_every_line_present() -> None:
    data = _cmu().replace(b"Frames: 2752", b"Frames: 100")
    m, notes = read(data)
    assert m.num_frames == 2752  # type: ignore[attr-defined]
    assert [(w.code, w.line) for w in notes] == [("frame_count", 186)]
