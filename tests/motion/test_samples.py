"""The bundled samples: present, documented, small, sharing one skeleton, named by ``sample:NAME``,
and reproducible from their sources (the 30 fps clips from ``../shared/data``, the MIDI song from
its recipe)."""

from __future__ import annotations

import gzip
import re
from pathlib import Path

import numpy as np
import pytest

from motion import MotionError
from motion.io import load_motion
from motion.resample import resample
from motion.samples import (
    SAMPLES,
    declared_units,
    is_clip_sample,
    resolve_path,
    sample_name,
    sample_path,
    upload_units,
)

SAMPLES_DIR = sample_path("walk").parent
SHARED = Path(__file__).resolve().parents[2].parent / "shared" / "data"
SOURCES = {
    "salsa-leader-02": "cmu-salsa/60_02_scaled.bvh",
    "salsa-follower-02": "cmu-salsa/61_02_scaled.bvh",
    "salsa-leader-04": "cmu-salsa/60_04_scaled.bvh",
    "salsa-follower-04": "cmu-salsa/61_04_scaled.bvh",
    "salsa-leader-05": "cmu-salsa/60_05_scaled.bvh",
    "salsa-follower-05": "cmu-salsa/61_05_scaled.bvh",
    "salsa-leader-12": "cmu-salsa/60_12_scaled.bvh",
    "walk-05-01": "cmu-daz/walks/05_01.bvh",
    "walk-10-04": "cmu-daz/walks/10_04.bvh",
    "walk-12-02": "cmu-daz/walks/12_02.bvh",
    "run-09-01": "cmu-daz/actions/09_01.bvh",
    "run-09-02": "cmu-daz/actions/09_02.bvh",
    "run-09-03": "cmu-daz/actions/09_03.bvh",
    "run-09-04": "cmu-daz/actions/09_04.bvh",
    "jump-13-11": "cmu-daz/actions/13_11.bvh",
    "jump-13-32": "cmu-daz/actions/13_32.bvh",
}
"""The resampled samples and the shared file each was made from."""


def test_every_sample_is_a_documented_packaged_file() -> None:
    doc = (SAMPLES_DIR / "SAMPLES.md").read_text()
    files = {p.name for p in SAMPLES_DIR.iterdir() if p.suffix in (".gz", ".mid")}
    assert files == set(SAMPLES.values())  # nothing bundled that is not a sample, and no sample missing
    for name, file in SAMPLES.items():
        assert f"`{name}`" in doc or re.search(rf"`{re.escape(name.rsplit('-', 1)[0])}-", doc), name
        assert file.split("_")[0] in doc or file in doc, file
    total = sum((SAMPLES_DIR / f).stat().st_size for f in SAMPLES.values())
    assert total < 4_000_000, f"the bundle is {total / 1e6:.1f} MB; keep it a few MB"
    originals = {"salsa-leader", "salsa-follower", "walk", "start-walk-stop", "song"}
    assert set(SOURCES) | originals == set(SAMPLES)
    # shipped with the package (pyproject's package data), not only present in a clone
    pyproject = (SAMPLES_DIR.parents[1] / "pyproject.toml").read_text()
    line = next(ln for ln in pyproject.splitlines() if ln.startswith('"motion.samples" = '))
    patterns = re.findall(r'"\*(\.[\w.]+)"', line)
    assert all(any(f.endswith(p) for p in patterns) for f in SAMPLES.values()), (patterns, line)


def test_the_cmu_clips_but_one_share_one_skeleton() -> None:
    first = load_motion("sample:walk").skeleton
    for name in SAMPLES:
        if not is_clip_sample(name) or name == "start-walk-stop":
            continue
        m = load_motion(f"sample:{name}")
        assert m.skeleton.same_structure(first), name
        assert m.num_joints == 43 or name == "walk"  # the walk's daz file adds End Site joints


def test_sample_references() -> None:
    assert sample_name("sample:walk") == "walk" and sample_name("walk.bvh") is None
    assert sample_name(Path("sample:walk")) is None  # only strings name samples
    assert resolve_path("sample:song") == SAMPLES_DIR / "song_104_116bpm.mid"
    assert resolve_path("a/b.bvh", Path("/spec")) == Path("/spec/a/b.bvh")
    assert resolve_path("/abs/b.bvh", Path("/spec")) == Path("/abs/b.bvh")
    with pytest.raises(MotionError, match="no bundled sample 'nope'; available: salsa-leader"):
        resolve_path("sample:nope")
    assert load_motion("sample:run-09-01").num_frames == 38
    assert is_clip_sample("walk") and not is_clip_sample("song") and not is_clip_sample("nope")


def test_the_song_is_its_recipe() -> None:
    from engines.rhythm.music import parse_midi, write_midi

    data = sample_path("song").read_bytes()
    assert data == write_midi([(0, 104.0), (7680, 116.0)], 15360)
    beats = parse_midi(data).beat_times()  # 32 beats and the end of the piece
    assert len(beats) == 33 and beats[-1] == pytest.approx(16 * 60 / 104 + 16 * 60 / 116, abs=1e-3)
    np.testing.assert_allclose(np.diff(beats)[:16], 60 / 104, atol=1e-4)
    np.testing.assert_allclose(np.diff(beats)[16:], 60 / 116, atol=1e-4)


@pytest.mark.skipif(not SHARED.is_dir(), reason=f"shared motion data not found under {SHARED}")
@pytest.mark.parametrize("name", sorted(SOURCES))
def test_resampled_samples_match_their_sources(name: str) -> None:
    """Each ``_30fps`` sample is its source resampled to 30 fps (``segue convert --fps 30``), to the
    six decimals BVH text keeps; gzip without a name or time stamp (``gzip -n``)."""
    source = load_motion(SHARED / SOURCES[name])
    bundled = load_motion(f"sample:{name}")
    expected = resample(source, 30.0)
    assert bundled.fps == pytest.approx(30.0, abs=1e-3) and bundled.num_frames == expected.num_frames
    height = float(np.ptp(source.global_positions()[..., 1]))
    err = np.abs(bundled.global_positions() - expected.global_positions()).max()
    assert err < 1e-4 * height, (name, err, height)
    header = sample_path(name).read_bytes()[:10]
    assert header[3] & 0x08 == 0 and header[4:8] == b"\0\0\0\0"  # no file name, no mtime
    assert gzip.decompress(sample_path(name).read_bytes()).startswith(b"HIERARCHY")


def test_salsa_samples_are_read_in_their_declared_unit() -> None:
    """The catalogue declares the salsa samples' unit (``cmu-scaled``, 1.28 m): 1.46 m dancers, not
    the 1.15 m the metre guess gives; other samples and plain files are guessed; a unit given wins."""
    from motion.units import standing_height

    for name in SAMPLES:
        if not name.startswith("salsa-"):
            assert declared_units(f"sample:{name}") is None
            continue
        assert declared_units(f"sample:{name}") == "cmu-scaled" == declared_units(sample_path(name))
    leader = load_motion("sample:salsa-leader-12")
    assert leader.units == "cmu-scaled"
    height_m = standing_height(leader.global_positions()[::10]) * leader.metres_per_unit
    assert 1.4 <= height_m <= 1.5
    assert load_motion(sample_path("salsa-follower-02")).units == "cmu-scaled"  # by the file, too
    assert load_motion("sample:salsa-leader-12", units="m").units == "m"
    assert load_motion("sample:walk").units == "cm"
    # a copy elsewhere is a plain file: read as guessed
    assert declared_units(Path("/tmp") / SAMPLES["salsa-leader-12"]) is None
    data = sample_path("salsa-leader-12").read_bytes()
    assert upload_units(SAMPLES["salsa-leader-12"], data) == "cmu-scaled"
    assert upload_units("my-leader.bvh.gz", data) is None
    assert upload_units(SAMPLES["salsa-leader-12"], data + b"\n") is None
    assert upload_units(SAMPLES["walk"], sample_path("walk").read_bytes()) is None
