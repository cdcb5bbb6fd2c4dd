"""Every BVH file of the shared data set (``../shared/data``): parse, FK, heights, round trip.

Global positions are checked against an independent reader and forward kinematics
(:mod:`bvh_helpers`: Python ``float`` tokens, per-axis rotation matrices) on every frame, to
1e-6 x the standing height; a write -> read round trip must reproduce them to 1e-5 x height.

Tests are parametrised by the file's path relative to the data folder, through a module-scoped
fixture so that pytest runs all checks of one file together and each file is loaded only once.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

import motion
from motion.bvh import bvh_text, detect_units, parse_bvh

from .bvh_helpers import RawBvh, RefPose, read_raw_bvh, reference_fk, reference_height

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"
FILES = sorted(DATA.rglob("*.bvh")) if DATA.is_dir() else []

if not FILES:
    pytest.skip(f"shared motion data not found under {DATA} (no *.bvh files)", allow_module_level=True)

pytestmark = pytest.mark.slow  # 734 files: tests/run.sh runs them with CI=true or SEGUE_SLOW=1

FK_TOL = 1e-6  # x standing height, library FK vs independent FK
ROUND_TRIP_TOL = 1e-5  # x standing height, positions after write -> read
FRAME_STEP = 1  # check the independent FK on every FRAME_STEP-th frame (1 = all frames)


@dataclass
class Loaded:
    """One shared file: the motion read by the library and the independent reading of it."""

    rel: str
    motion: motion.Motion
    positions: np.ndarray  # library global positions (F, J, 3), file units
    end_sites: np.ndarray  # library End Site positions (F, E, 3)
    raw: RawBvh
    ref: RefPose
    height: float  # standing height from the reference FK (joints and End Sites), file units

    def __repr__(self) -> str:  # keep assertion output short
        return f"Loaded({self.rel!r})"


@pytest.fixture(scope="module", params=FILES, ids=[str(f.relative_to(DATA)) for f in FILES])
def loaded(request: pytest.FixtureRequest) -> Loaded:
    path: Path = request.param
    data = path.read_bytes()
    m = motion.read_bvh(path)
    raw = read_raw_bvh(data)
    ref = reference_fk(raw, slice(None, None, FRAME_STEP))
    height = reference_height(np.concatenate((ref.positions, ref.end_sites), axis=1))
    pos, grot = m.fk()
    ends = m.end_site_positions(pos, grot)
    return Loaded(str(path.relative_to(DATA)), m, pos, ends, raw, ref, height)


def test_parse_matches_reference_reader(loaded: Loaded) -> None:
    m, raw = loaded.motion, loaded.raw
    sk = m.skeleton
    assert m.num_frames == raw.frames, f"{loaded.rel}: frame count"
    assert list(sk.names) == raw.names, f"{loaded.rel}: joint names"
    assert sk.parents.tolist() == raw.parents, f"{loaded.rel}: parents"
    assert [list(c) for c in sk.channels] == raw.channels, f"{loaded.rel}: channel layout"
    np.testing.assert_array_equal(sk.offsets, np.array(raw.offsets), err_msg=f"{loaded.rel}: offsets")
    assert sk.end_site_parents.tolist() == raw.end_site_parents, f"{loaded.rel}: End Site parents"
    np.testing.assert_array_equal(
        sk.end_site_offsets, np.array(raw.end_site_offsets).reshape(-1, 3), err_msg=f"{loaded.rel}: End Sites"
    )
    expected_fps = 1.0 / raw.frame_time
    assert abs(m.fps - expected_fps) <= 1e-3 * expected_fps, f"{loaded.rel}: fps {m.fps} vs {expected_fps}"
    assert m.fps == round(m.fps), f"{loaded.rel}: fps {m.fps} should snap to an integer rate"


def test_fk_is_finite(loaded: Loaded) -> None:
    pos = loaded.positions
    assert pos.shape == (loaded.motion.num_frames, loaded.motion.num_joints, 3)
    assert np.isfinite(pos).all(), f"{loaded.rel}: non-finite global positions"
    assert np.isfinite(loaded.end_sites).all(), f"{loaded.rel}: non-finite End Site positions"
    assert np.isfinite(loaded.motion.rotations).all(), f"{loaded.rel}: non-finite rotations"
    norms = np.linalg.norm(loaded.motion.rotations, axis=-1)
    assert np.abs(norms - 1.0).max() < 1e-9, f"{loaded.rel}: rotations are not unit quaternions"


def test_height_is_plausible(loaded: Loaded) -> None:
    guess = detect_units(loaded.motion)
    assert guess.plausible or 0.9 <= guess.height_m <= 2.4, (
        f"{loaded.rel}: implausible standing height {guess.height_m:.3f} m "
        f"({guess.height:.3f} file units read as {guess.units})"
    )
    assert (
        loaded.motion.units == guess.units
    ), f"{loaded.rel}: units {loaded.motion.units} vs guess {guess.units}"
    # The library's height agrees with the independent one (same definition, fewer frames sampled).
    assert (
        abs(guess.height - loaded.height) <= 0.05 * loaded.height
    ), f"{loaded.rel}: height {guess.height} vs independent {loaded.height}"


def test_fk_matches_independent_fk(loaded: Loaded) -> None:
    lib = loaded.positions[::FRAME_STEP]
    err = np.abs(lib - loaded.ref.positions).max(axis=(0, 2))  # per joint
    worst = int(np.argmax(err))
    assert err[worst] <= FK_TOL * loaded.height, (
        f"{loaded.rel}: joint {loaded.raw.names[worst]!r} off by {err[worst]:.3g} "
        f"(= {err[worst] / loaded.height:.3g} x height {loaded.height:.4g})"
    )
    if loaded.end_sites.size:
        end_err = float(np.abs(loaded.end_sites[::FRAME_STEP] - loaded.ref.end_sites).max())
        assert end_err <= FK_TOL * loaded.height, f"{loaded.rel}: End Sites off by {end_err:.3g}"


def test_round_trip_reproduces_positions(loaded: Loaded) -> None:
    m = loaded.motion
    again = parse_bvh(bvh_text(m).encode("utf-8"))
    assert again.skeleton.names == m.skeleton.names, f"{loaded.rel}: names changed"
    assert again.skeleton.channels == m.skeleton.channels, f"{loaded.rel}: channel layout changed"
    assert np.array_equal(again.skeleton.parents, m.skeleton.parents), f"{loaded.rel}: parents changed"
    assert again.num_frames == m.num_frames and again.fps == m.fps, f"{loaded.rel}: frames/fps changed"
    err = float(np.abs(again.global_positions() - loaded.positions).max())
    assert (
        err <= ROUND_TRIP_TOL * loaded.height
    ), f"{loaded.rel}: round trip moved a joint by {err:.3g} (= {err / loaded.height:.3g} x height)"


def test_cmu_salsa_scaled_unit_is_the_daz_figure_over_128() -> None:
    """The true scale of the CMU salsa "scaled" files (motion.units, ``cmu-scaled``): their skeleton
    is the CMU-Daz figure (centimetres) divided by 128, and the Daz figure falls at about g."""
    salsa_path, daz_path = DATA / "cmu-salsa" / "60_02_scaled.bvh", DATA / "cmu-daz" / "walks" / "07_01.bvh"
    jump_path = DATA / "cmu-daz" / "actions" / "13_11.bvh"
    if not (salsa_path.exists() and daz_path.exists() and jump_path.exists()):
        pytest.skip("../shared/data (CMU salsa and CMU-Daz) is not here")
    salsa = motion.read_bvh(salsa_path, units="cmu-scaled")
    daz = motion.read_bvh(daz_path)
    assert daz.units == "cm" and salsa.skeleton.names == daz.skeleton.names
    big = np.abs(daz.skeleton.offsets) > 1.0
    ratio = salsa.skeleton.offsets[big] / daz.skeleton.offsets[big]
    np.testing.assert_allclose(ratio, 1 / 128, rtol=2e-3)
    h = motion.read_bvh(salsa_path).global_positions()  # the guess: metres, a 1.14 m dancer
    assert 1.0 < np.ptp(h[0, :, 1]) < 1.3
    assert 1.35 < np.ptp(salsa.global_positions()[0, :, 1]) * salsa.metres_per_unit < 1.7
    jump = motion.read_bvh(jump_path)  # free fall of the hips in centimetres: about g
    y = jump.global_positions()[:, 0, 1]
    feet = jump.global_positions()[:, [jump.skeleton.names.index(n) for n in ("lFoot", "rFoot")], 1].min(1)
    air = np.flatnonzero(feet > np.percentile(feet, 5) + 8.0)
    run = air[: np.argmax(np.diff(air) > 1)] if np.any(np.diff(air) > 1) else air
    g = -2 * np.polyfit(run / jump.fps, y[run], 2)[0] / 100
    assert 8.5 < g < 10.5
