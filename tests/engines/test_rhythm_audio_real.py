"""Music beats of REAL recordings (engines/rhythm/audio.py), from other beat-tracking projects'
public test data. None of it is bundled; each test skips, saying why, when its file is absent.

* madmom's ``tests/data/audio/sample.wav``: a 2.8 s drum-and-bass break at 87.5 BPM with four
  hand-annotated beats (``tests/data/annotations/sample.beats``). madmom's data files are
  CC BY-NC-SA 4.0 (not for this MIT project's repository) and its PyPI sdist does not carry its
  tests, so the test reads them from ``$SEGUE_BEAT_DATA/madmom/`` (default
  ``~/.cache/segue/beat-data/madmom/``; copy the two files there from a madmom checkout).
* BeatNet's ``src/BeatNet/test_data/808kick120bpm.mp3`` (CC BY 4.0, BeatNet 1.1.3 by Mojtaba
  Heydari): a 10 s 808 kick loop at 120 BPM, fetched once from its PyPI sdist (sha256 checked)
  into ``$SEGUE_BEAT_DATA``; skipped when PyPI cannot be reached.
"""

from __future__ import annotations

import hashlib
import os
import re
import tarfile
import urllib.request
from pathlib import Path

import numpy as np
import pytest

from engines.rhythm.audio import audio_beats

from .audio_synthetic import f_measure

DATA = Path(os.environ.get("SEGUE_BEAT_DATA", Path.home() / ".cache" / "segue" / "beat-data"))
MADMOM = DATA / "madmom"
BEATNET_SDIST = "BeatNet-1.1.3.tar.gz"
BEATNET_SHA256 = "bb76dd00561562602b63fa301ffedef55fb87a484ce80a230d8914cd3c39bd43"
BEATNET_KICK = "BeatNet-1.1.3/src/BeatNet/test_data/808kick120bpm.mp3"


def metrical_f(found: np.ndarray, beats: np.ndarray) -> float:
    """The best F-measure (+-70 ms) of ``found`` against the beats, their double (the half-beats
    added) or their half (every other beat, either phase)."""
    double = np.sort(np.concatenate([beats, beats[:-1] + np.diff(beats) / 2]))
    return max(f_measure(found, b) for b in (beats, double, beats[::2], beats[1::2]))


def test_madmom_drum_and_bass_sample_at_its_tempo() -> None:
    wav, ann = MADMOM / "sample.wav", MADMOM / "sample.beats"
    if not (wav.is_file() and ann.is_file()):
        pytest.skip(
            f"madmom's sample.wav and sample.beats not in {MADMOM} (CC BY-NC-SA 4.0 test data of "
            "github.com/CPJKU/madmom, tests/data/audio and tests/data/annotations: not bundled)"
        )
    beats = np.loadtxt(ann, comments="#", ndmin=2)[:, 0]
    found = audio_beats(wav.read_bytes())
    assert metrical_f(found.beats_s, beats) >= 0.75
    assert f_measure(found.beats_s, beats) >= 0.75  # (was 0.44 at 117 BPM under the prior alone)
    assert 80 <= found.tempo_bpm <= 95
    assert found.tempo_confidence is not None and found.tempo_confidence > 0.5


def _beatnet_kick() -> bytes:
    """The kick loop, from the cached sdist or fetched once from PyPI (skips when unreachable)."""
    sdist = DATA / BEATNET_SDIST
    if not sdist.is_file():
        try:
            index = urllib.request.urlopen("https://pypi.org/simple/beatnet/", timeout=20).read().decode()
            url = next(u for u in re.findall(r'href="([^"#]+)', index) if u.endswith("/" + BEATNET_SDIST))
            data = urllib.request.urlopen(url, timeout=120).read()
        except (OSError, StopIteration) as exc:
            pytest.skip(f"PyPI unreachable or {BEATNET_SDIST} not listed ({exc}): BeatNet's test recording")
        if hashlib.sha256(data).hexdigest() != BEATNET_SHA256:
            pytest.fail(f"{BEATNET_SDIST} from PyPI does not have the expected sha256")
        DATA.mkdir(parents=True, exist_ok=True)
        tmp = sdist.with_suffix(".part")
        tmp.write_bytes(data)
        tmp.replace(sdist)
    with tarfile.open(sdist) as tar:
        member = tar.extractfile(BEATNET_KICK)
        assert member is not None
        return member.read()


def test_beatnet_808_kick_loop_at_120_bpm() -> None:
    found = audio_beats(_beatnet_kick())
    assert found.tempo_bpm == pytest.approx(120.0, abs=1.0)
    ibi = np.diff(found.beats_s)
    assert np.abs(ibi - 0.5).max() < 0.03  # every beat, none skipped or doubled
    assert found.beats_s[0] < 1.0 and found.beats_s[-1] > found.duration_s - 1.5
    assert found.tempo_confidence is not None and found.tempo_confidence > 0.9


def test_metrical_f_counts_double_and_half() -> None:
    beats = np.arange(0.5, 10.0, 0.5)
    assert metrical_f(beats[::2] + 0.01, beats) == pytest.approx(1.0)
    assert metrical_f(np.arange(0.5, 9.6, 0.25), beats) == pytest.approx(1.0)
    assert metrical_f(beats + 0.125, beats) == 0.0
