"""Beat keys and beat clarity of basic movements (engines/rhythm/beatkeys.py)."""

from __future__ import annotations

import numpy as np

from engines.rhythm.beatkeys import beat_keys, movement_speed, warp_frames

P, B = 40, 4


def _dips(at: list[float], width: float = 4.0) -> np.ndarray:
    """A speed profile ``(B P,)`` of 1 with Gaussian dips to 0.1 at movement frames ``at``."""
    u = np.arange(B * P) + 0.5
    s = np.ones_like(u)
    for a in at:
        s -= 0.9 * np.exp(-0.5 * ((u - a) / width) ** 2)
    return s


def test_keys_follow_the_speed_dips_and_the_ends_stay() -> None:
    speed = _dips([0, 44, 76, 125, 160])[None]
    keys, clarity = beat_keys(speed, P, B)
    np.testing.assert_allclose(keys[0], [0, 44, 76, 125, 160], atol=1.0)
    assert clarity[0] > 0.9


def test_extra_dips_between_beats_lower_the_clarity() -> None:
    clean = _dips([0, 40, 80, 120, 160])
    busy = _dips([0, 20, 40, 60, 80, 100, 120, 140, 160])
    flat = np.ones(B * P)
    _, clarity = beat_keys(np.stack((clean, busy, flat)), P, B)
    assert clarity[0] > 0.9 and clarity[1] < 0.7 * clarity[0] and clarity[2] < 0.3


def test_no_dip_near_a_beat_keeps_the_nominal_frame() -> None:
    keys, _ = beat_keys(_dips([0, 80, 160])[None], P, B)
    assert keys[0, 1] == 40 and keys[0, 3] == 120 and abs(keys[0, 2] - 80) <= 1


def test_warp_is_linear_between_keys() -> None:
    keys = np.array([0.0, 44.0, 76.0, 125.0, 160.0])
    beat = np.array([0, 0, 1, 3, 3])
    x = np.array([0.0, 0.5, 1.0, 0.0, 1.0])
    np.testing.assert_allclose(warp_frames(keys, beat, x), [0, 22, 76, 125, 160])


def test_movement_speed_sums_joint_speeds() -> None:
    pos = np.zeros((1, 3, 2, 3))
    pos[0, :, 0, 0] = [0, 1, 3]
    pos[0, :, 1, 1] = [0, 2, 2]
    np.testing.assert_allclose(movement_speed(pos), [[3, 2]])
