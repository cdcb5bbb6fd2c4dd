"""The bounded BVH header read: the facts and header errors of a full parse, in bounded memory."""

from __future__ import annotations

import gzip
import tracemalloc

import numpy as np
import pytest

from motion import BvhError, BvhLimits, parse_bvh
from motion.bvh_header import bvh_first_frames, bvh_header
from motion.retarget.transfer import zero_pose
from motion.samples import SAMPLES, sample_path

CLIPS = [name for name, file in SAMPLES.items() if file.endswith(".bvh.gz")]


@pytest.mark.parametrize("name", CLIPS[:6])
def test_the_header_says_what_the_parse_finds(name: str) -> None:
    data = sample_path(name).read_bytes()
    motion, head = parse_bvh(data), bvh_header(data)
    assert head.joints == motion.skeleton.names and head.frames == motion.num_frames
    assert head.fps == motion.fps and head.channels == motion.skeleton.num_channels
    assert head.text_bytes == len(gzip.decompress(data))
    first = parse_bvh(bvh_first_frames(data, 1) or b"", units=motion.units)
    for a, b in ((motion.slice(0, 1), first), (zero_pose(motion), zero_pose(first))):
        assert np.array_equal(a.rotations, b.rotations)
        assert np.array_equal(a.root_positions, b.root_positions) and a.fps == b.fps


def _text(frames: int) -> bytes:
    data = gzip.decompress(sample_path("walk").read_bytes()).decode()
    head, _, rest = data.partition("Frames:")
    row = rest.split("\n")[2]
    return f"{head}Frames: {frames}\nFrame Time: 0.0083333\n".encode() + (row + "\n").encode() * frames


def test_header_errors_are_the_parsers() -> None:
    text = _text(3)
    for bad in (
        text.replace(b"Frames: 3", b"Frames: three"),
        text.replace(b"Frame Time: 0.0083333", b"Frame Time: 99"),
        text.replace(b"ROOT", b"ROTO"),
        text.replace(b"Frames: 3", b"Frames: 30000"),
    ):
        limits = BvhLimits(max_frames=20_000)
        with pytest.raises(BvhError) as full:
            parse_bvh(bad, limits=limits, source="x.bvh")
        with pytest.raises(BvhError) as head:
            bvh_header(bad, limits, "x.bvh")
        assert str(head.value) == str(full.value)


def test_a_gzip_bomb_is_measured_in_bounded_memory() -> None:
    frames = 200_000
    data = gzip.compress(_text(frames), 9)  # ~100 MB of text in ~1 MB
    tracemalloc.start()
    try:
        head = bvh_header(data, BvhLimits(max_bytes=1 << 30))
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert head.frames == frames and head.text_bytes > 50 << 20
    assert peak < 16 << 20  # a few inflate chunks and the header, never the text
    with pytest.raises(BvhError, match="decompressed file is larger than the 1000000-byte limit"):
        bvh_header(data, BvhLimits(max_bytes=1_000_000))
