"""Reference-pose frames at the start of CMU-Daz clips (motion.refpose)."""

from __future__ import annotations

import numpy as np
import pytest

from motion.io import load_motion
from motion.refpose import reference_lead, without_reference_lead

from .synthetic import walking_biped


@pytest.mark.parametrize(
    ("name", "lead"),
    [("walk", 4), ("salsa-leader", 4), ("walk-05-01", 1), ("salsa-follower-02", 1), ("start-walk-stop", 0)],
)
def test_the_samples_reference_pose_lead(name: str, lead: int) -> None:
    m = load_motion(f"sample:{name}")
    assert reference_lead(m) == lead
    trimmed, dropped = without_reference_lead(m)
    assert dropped == lead and trimmed.num_frames == m.num_frames - lead
    pos = trimmed.global_positions() * trimmed.metres_per_unit
    first_step = np.linalg.norm(pos[1] - pos[0], axis=-1).max() * m.fps
    assert first_step < 8.0  # m/s: no joint jumps out of a T-pose (the walk's hand did 24 m/s)


def test_clips_without_a_lead_are_kept_whole() -> None:
    m = load_motion("sample:walk")
    assert reference_lead(m.slice(4, None)) == 0  # already trimmed
    assert reference_lead(m.slice(0, 2)) == 0  # too short to tell
    assert reference_lead(walking_biped(frames=60)) == 0
