"""engines.library: mirror images of a library's clips share the skeleton's conventions; time-scaled
copies play the clips at other speeds."""

from __future__ import annotations

import numpy as np
import pytest

from engines.graph.engine import GraphEngine
from engines.library import (
    MIRROR_SUFFIX,
    MotionLibrary,
    clip_sources,
    speeds_frames,
    with_mirrors,
    with_speeds,
)
from engines.registry import parse_database_spec
from motion import MotionError
from motion import rotations as rot
from motion.mirror import joint_frames, mirror_map

from ..motion.synthetic import rerigged, walking_biped


def test_mirror_images_share_the_skeletons_conventions() -> None:
    # a rig whose bones run along local axes (as Bandai-Namco's): every image keeps the rig, with
    # the same joint frames for every clip (chosen over all of them), so clips and images can be
    # cut together and blended
    quarter = rot.from_axis_angle(np.array([0.0, 0.0, 1.0]), np.pi / 2)
    clips = tuple(rerigged(walking_biped(seed=s, heading_deg=h), quarter) for s, h in ((0, 0.0), (1, 70.0)))
    lib = with_mirrors(MotionLibrary(("a", "b"), clips, ((), ())))
    assert lib.names == ("a", "b", "a" + MIRROR_SUFFIX, "b" + MIRROR_SUFFIX)
    partner, _ = mirror_map(clips[0].skeleton.names)
    frames = joint_frames(clips)
    np.testing.assert_allclose(np.abs(np.einsum("jk,jk->j", frames, joint_frames(clips[0]))), 1.0)
    for clip, image in zip(lib.motions[:2], lib.motions[2:], strict=True):
        expected = clip.global_positions()[:, partner] * np.array([-1.0, 1, 1])
        np.testing.assert_allclose(image.global_positions(), expected, atol=1e-12)
        np.testing.assert_allclose(image.skeleton.offsets, clip.skeleton.offsets, atol=1e-12)


def test_time_scaled_copies_play_the_clips_at_each_speed() -> None:
    clip = walking_biped(91, seed=0)  # 3 s at 30 fps
    labels = ({"label": "walk", "start": 9, "end": 91, "value": 1},)
    lib = with_speeds(MotionLibrary(("a",), (clip,), (labels,)), [0.75, 1.5])
    assert lib.names == ("a", "a (x0.75)", "a (x1.5)")
    slow, fast = lib.motions[1], lib.motions[2]
    assert (slow.num_frames, fast.num_frames) == (121, 61) and slow.fps == fast.fps == clip.fps
    assert [m.name for m in lib.motions[1:]] == list(lib.names[1:])
    pos = clip.global_positions()
    # copy frame k shows the clip's frame k * speed (whole frames here: no interpolation)
    np.testing.assert_allclose(slow.global_positions()[::4], pos[::3], atol=1e-9)
    np.testing.assert_allclose(fast.global_positions()[::2], pos[::3], atol=1e-9)
    # labels cover the same moments of the copy: [9, 91) -> [12, 121) and [6, 61)
    assert lib.labels[1] == ({"label": "walk", "start": 12, "end": 121, "value": 1},)
    assert lib.labels[2] == ({"label": "walk", "start": 6, "end": 61, "value": 1},)
    assert speeds_frames(91, [0.75, 1.5]) == 91 + 122 + 61  # within a frame a clip of the copies'
    assert with_speeds(lib, []) is lib


def test_mirror_and_speeds_make_every_combination() -> None:
    clips = (walking_biped(60, seed=0), walking_biped(60, seed=1, heading_deg=70.0))
    spec = parse_database_spec(
        {"kind": "graph", "clips": [{"bvh": "a.bvh"}, {"bvh": "b.bvh"}], "mirror": True, "speeds": [0.9]}
    )
    lib = GraphEngine.library_for(spec, MotionLibrary(("a", "b"), clips, ((), ())))
    assert lib.names == (
        "a",
        "b",
        "a (mirror)",
        "b (mirror)",
        "a (x0.9)",
        "b (x0.9)",
        "a (mirror) (x0.9)",
        "b (mirror) (x0.9)",
    )
    mirrored = lib.clip("a (mirror)").global_positions()
    np.testing.assert_allclose(
        lib.clip("a (mirror) (x0.9)").global_positions()[::10], mirrored[::9], atol=1e-9
    )
    assert abs(GraphEngine.library_frames(spec, 120) - lib.total_frames) <= len(clips) * 2
    # each stored clip's source, where the summary finds its units: the layout just built
    sources = GraphEngine.clip_sources(spec.model_dump(mode="json"), len(lib.names))
    assert [lib.names[0 if s is None else s] for s in sources] == ["a", "b"] * 4
    assert [n.startswith("a") for n in lib.names] == [s == 0 for s in sources]


def test_clip_sources_of_a_library_laid_out_otherwise_name_only_the_clips() -> None:
    assert clip_sources(2, 3, 6) == [0, 1, 0, 1, 0, 1]
    assert clip_sources(2, 3, 5) == [0, 1, None, None, None]  # not the layout: no guess
    assert clip_sources(0, 2, 1) == [None]


def test_a_copys_name_must_be_free() -> None:
    clip = walking_biped(30, seed=0)
    with pytest.raises(MotionError, match="a \\(x0.9\\)"):
        with_speeds(MotionLibrary(("a", "a (x0.9)"), (clip, clip), ((), ())), [0.9])
