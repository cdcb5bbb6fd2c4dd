"""engines.library: mirror images of a library's clips share the skeleton's conventions."""

from __future__ import annotations

import numpy as np

from engines.library import MIRROR_SUFFIX, MotionLibrary, with_mirrors
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
