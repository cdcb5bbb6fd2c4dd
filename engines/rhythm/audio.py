"""Music beats from a recording (WAV, FLAC, Ogg Vorbis, MP3): decoding and beat tracking.

Decoding uses soundfile (libsndfile reads WAV, FLAC, Ogg and, from libsndfile 1.1 on, MP3), with
librosa's audioread fallback for what it cannot read. Beat tracking uses librosa:

1. the onset strength envelope (spectral flux of a mel spectrogram, ``HOP`` samples per frame);
2. the tempo *at every frame* (:func:`librosa.feature.tempo` with ``aggregate=None``: the
   autocorrelation tempogram of an ~8 s window under a log-normal prior centred on
   ``DANCE_TEMPO_BPM``, the middle of dance music's 90-140 BPM), smoothed over ``TEMPO_SMOOTH_S``,
   so a tempo that drifts is followed; with a ``tempo_bpm`` hint the prior is centred there and
   narrow instead;
2b. the metrical level, from the onsets' periodicity (:func:`choose_level`; not with a hint): the
   prior picks the tempogram's strongest peak near 115 BPM, which may be a grouping of the beat's
   subdivisions that is no metrical level at all (a drum-and-bass break at 87.5 BPM has its
   strongest periodicity at 117 BPM: three of its eighth notes). A beat level is periodic *and*
   so is its half (the beat divides in two), so each candidate ``r`` times the prior's tempo
   (``LEVEL_RATIOS``) is scored by the tempogram at the beat period plus at half of it, frame by
   frame at the local tempo, averaged. A candidate that beats the prior's by ``LEVEL_MARGIN``
   replaces it, at the octave (it, its half or its double) the prior likes best: the prior is only
   the tie-breaker between octaves. The confidence is the chosen level's score over the sum of it
   and the best rival level's (not its octave): 0.5 when another level is as periodic, 1 when
   none is;
3. Ellis' dynamic-programming beat tracker (:func:`librosa.beat.beat_track`) with that
   time-varying tempo (a single global tempo loses the beat when the tempo drifts: a 96 -> 116 BPM
   track drifts a quarter of a beat in 4 s);
4. a beat the DP skipped (an interval of about two or more local periods) is put back, and each
   beat is moved to the strongest onset within ``REFINE`` of a period (the DP lands on the
   envelope's frame grid and leans towards its tempo), at sub-frame precision (parabola through
   the peak's neighbours).

Downbeats: with ``meter`` beats per bar, the bar phase whose beats carry the most power below
``DOWNBEAT_MAX_HZ`` (median over the bars of the first 60 ms after each beat: a kick drum or bass
on the bar's first beat) is the downbeat when it stands out from every other phase by
``DOWNBEAT_MARGIN``; otherwise none is claimed.

beat_this (Foscarin et al. 2024) is stronger on real recordings, but it needs torch and downloads
its checkpoint at first use, which this project does not allow (no download at first use).
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from .music import MusicError
from .music_facts import audio_channels, channel_problem

Array = npt.NDArray[np.float64]

SR = 22050
"""Analysis sample rate, Hz (the recording is resampled to it, mono)."""
HOP = 256
"""Onset-envelope hop, samples (11.6 ms at ``SR``)."""
DANCE_TEMPO_BPM = 115.0
"""Centre of the tempo prior (log-normal), BPM."""
DANCE_TEMPO_OCTAVES = 0.4
"""Standard deviation of the tempo prior, octaves (``log2`` BPM)."""
HINT_OCTAVES = 0.1
"""Standard deviation of the tempo prior around a ``tempo_bpm`` hint, octaves."""
TEMPO_SMOOTH_S = 4.0
"""Smoothing of the per-frame tempo, seconds (median filter)."""
REFINE = 0.15
"""A beat is moved to the strongest onset within this fraction of a period."""
DOWNBEAT_MARGIN = 1.5
"""The downbeat phase's low-frequency power must exceed every other phase's by this factor."""
DOWNBEAT_MAX_HZ = 150.0
"""Upper frequency of the band (kick drum, bass) whose power marks the downbeat, Hz."""
LEVEL_RATIOS = (1.0, 2.0 / 3.0, 3.0 / 4.0, 4.0 / 3.0, 3.0 / 2.0)
"""Candidate beat levels, as multiples of the prior's tempo (octaves of these are the prior's choice)."""
LEVEL_MARGIN = 1.2
"""A candidate level replaces the prior's when its periodicity score is this many times as high
(and at least ``LEVEL_MIN_GAIN`` higher)."""
LEVEL_MIN_GAIN = 0.1
"""Smallest score gain for a change of level (tempogram units: 1 = perfectly periodic)."""
MAX_SECONDS = 3600.0
"""Longest recording accepted, seconds."""
SILENCE_RMS = 1e-4
"""A recording whose RMS (full scale = 1) is below this is silent."""
MIN_BEATS = 4
"""Fewer beats than this: no detectable beat."""


def audio_media_type(head: bytes) -> str | None:
    """The media type of audio content from its first bytes (magic numbers), None when not audio:
    ``RIFF....WAVE``, ``fLaC``, ``OggS``, MP3 (an ``ID3`` tag or an MPEG audio frame sync)."""
    if head[:4] == b"RIFF" and head[8:12] == b"WAVE":
        return "audio/wav"
    if head[:4] == b"fLaC":
        return "audio/flac"
    if head[:4] == b"OggS":
        return "audio/ogg"
    if head[:3] == b"ID3" or (len(head) > 1 and head[0] == 0xFF and head[1] & 0xE0 == 0xE0):
        return "audio/mpeg"
    return None


@dataclass(frozen=True, slots=True)
class AudioBeats:
    """Beats found in a recording.

    Attributes
    ----------
    beats_s: ``(B,)`` beat times, seconds from the start of the recording.
    tempo_bpm: median tempo (60 / median inter-beat interval).
    downbeat: index into ``beats_s`` of the first downbeat (bar start), None when none is clear.
    duration_s: length of the recording, seconds.
    tempo_confidence: in [0, 1], how clearly the onsets' periodicity picks this metrical level over
        every other (:func:`choose_level`; 0.5: another level is as periodic); None with a tempo hint.
    """

    beats_s: Array
    tempo_bpm: float
    downbeat: int | None
    duration_s: float
    tempo_confidence: float | None = None


def decode(data: bytes) -> tuple[Array, float]:
    """Mono samples ``(S,)`` (full scale 1) at ``SR`` Hz and the original length in seconds.

    Raises :class:`MusicError` for content that is not decodable audio, longer than
    ``MAX_SECONDS``, or silent."""
    import soundfile as sf

    if audio_media_type(data[:16]) is None:
        raise MusicError("audio: not a WAV, FLAC, Ogg or MP3 file (unrecognized content)")
    too_many = channel_problem(audio_channels(data))
    if too_many is not None:
        raise MusicError(too_many)
    y: Any
    try:
        info = sf.info(io.BytesIO(data))
        if info.duration > MAX_SECONDS:
            raise MusicError(f"audio: the recording lasts {info.duration:.0f} s; the limit is one hour")
        y, sr = sf.read(io.BytesIO(data), dtype="float32", always_2d=True)
        y = y.mean(axis=1)
    except MusicError:
        raise
    except Exception as exc:  # libsndfile: unsupported or corrupt; try audioread (mp3 on old libsndfile)
        y, sr = _audioread(data, exc)
    duration = y.size / float(sr)
    if duration > MAX_SECONDS:
        raise MusicError(f"audio: the recording lasts {duration:.0f} s; the limit is one hour")
    if y.size == 0 or not np.isfinite(y).all():
        raise MusicError("audio: the file holds no samples")
    if float(np.sqrt(np.mean(np.square(y, dtype=np.float64)))) < SILENCE_RMS:
        raise MusicError("audio: the recording is silent")
    if sr != SR:
        import librosa

        y = librosa.resample(y, orig_sr=sr, target_sr=SR, res_type="soxr_hq")
    return np.asarray(y, dtype=np.float64), duration


def _audioread(data: bytes, first: Exception) -> tuple[Any, int]:
    import os
    import tempfile

    try:
        import audioread
    except ImportError:
        raise MusicError(f"audio: cannot decode the file ({first})") from None
    fd, tmp = tempfile.mkstemp(suffix=".audio")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        with audioread.audio_open(tmp) as f:
            sr, ch = int(f.samplerate), int(f.channels)
            if f.duration > MAX_SECONDS:
                raise MusicError(f"audio: the recording lasts {f.duration:.0f} s; the limit is one hour")
            raw = b"".join(f)
    except MusicError:
        raise
    except Exception:
        raise MusicError(f"audio: cannot decode the file ({first})") from None
    finally:
        os.unlink(tmp)
    y = np.frombuffer(raw, dtype="<i2").astype(np.float32) / 32768.0
    return y.reshape(-1, max(ch, 1)).mean(axis=1), sr


def track_beats(y: Array, tempo_bpm: float | None = None, meter: int = 4) -> AudioBeats:
    """Beats of mono samples ``y (S,)`` at ``SR`` Hz (module doc); ``tempo_bpm``: a tempo hint.

    Raises :class:`MusicError` when no beat is found."""
    import librosa
    import scipy.ndimage as ndi
    from scipy.stats import lognorm

    oenv = librosa.onset.onset_strength(y=y.astype(np.float32), sr=SR, hop_length=HOP, aggregate=np.median)
    if oenv.size < 16 or float(oenv.max()) <= 1e-6:
        raise MusicError("audio: no detectable beat (no onsets)")
    centre = float(tempo_bpm) if tempo_bpm else DANCE_TEMPO_BPM
    octaves = HINT_OCTAVES if tempo_bpm else DANCE_TEMPO_OCTAVES
    prior = lognorm(s=octaves * np.log(2.0), scale=centre)
    local = librosa.feature.tempo(
        onset_envelope=oenv, sr=SR, hop_length=HOP, aggregate=None, prior=prior, max_tempo=320.0
    )
    fps = SR / HOP
    local = ndi.median_filter(np.asarray(local, dtype=np.float64), size=max(1, int(TEMPO_SMOOTH_S * fps)))
    confidence = None
    if not tempo_bpm:
        ratio, confidence = choose_level(oenv, local, prior)
        local = local * ratio
    _, frames = librosa.beat.beat_track(
        onset_envelope=oenv, sr=SR, hop_length=HOP, bpm=local, units="frames", trim=True
    )
    frames = np.asarray(frames, dtype=np.float64)
    if frames.size < MIN_BEATS:
        raise MusicError("audio: no detectable beat")
    beats = _refine(oenv, _fill_gaps(frames)) / fps
    beats = np.unique(np.round(beats, 6))
    if beats.size < MIN_BEATS:
        raise MusicError("audio: no detectable beat")
    tempo = 60.0 / float(np.median(np.diff(beats)))
    down = _downbeat(y, beats, meter)
    return AudioBeats(beats, tempo, down, y.size / SR, confidence)


def level_scores(oenv: npt.NDArray[Any], local: Array, ratios: tuple[float, ...] = LEVEL_RATIOS) -> Array:
    """``(R,)`` how periodic the onsets are at each candidate beat level ``ratios[i] * local``:
    the autocorrelation tempogram of ``oenv (T,)`` (onset envelope, ``HOP`` frames; each frame's
    column normalized to 1 at lag 0) at the beat period plus at half of it, read at every frame
    at its local tempo ``local (T,)`` (BPM) and averaged over the frames. 2 = perfectly periodic
    at both; about 0 or below = no periodicity there."""
    import librosa

    tg = np.asarray(librosa.feature.tempogram(onset_envelope=oenv, sr=SR, hop_length=HOP), dtype=np.float64)
    lags, frames = tg.shape
    cols = np.arange(frames)
    out = np.empty(len(ratios))
    for i, r in enumerate(ratios):
        total = np.zeros(frames)
        for lag in (60.0 * SR / HOP / (local[:frames] * r), 30.0 * SR / HOP / (local[:frames] * r)):
            lo = np.clip(np.floor(lag).astype(np.intp), 0, lags - 2)
            w = np.clip(lag - lo, 0.0, 1.0)
            total += (1.0 - w) * tg[lo, cols] + w * tg[lo + 1, cols]
        out[i] = float(total.mean())
    return out


def choose_level(oenv: npt.NDArray[Any], local: Array, prior: Any) -> tuple[float, float]:
    """The factor to apply to the prior's per-frame tempo ``local (T,)`` (BPM) to get the beat
    level, and the confidence in that level (module doc, step 2b). ``prior``: the tempo prior
    (a frozen scipy distribution over BPM) that chooses between octaves."""
    scores = level_scores(oenv, local)
    best = int(np.argmax(scores))
    gain = scores[best] - scores[0]
    if best == 0 or scores[best] < LEVEL_MARGIN * max(scores[0], 0.0) or gain < LEVEL_MIN_GAIN:
        best = 0
    base = LEVEL_RATIOS[best]
    ratio = 1.0  # the prior's own pick is its favourite octave already
    if best != 0:  # else the octave of the chosen level the prior likes best (at the median tempo)
        centre = float(np.median(local)) * base
        octaves = [o for o in (0.5, 1.0, 2.0) if 30.0 <= centre * o <= 320.0] or [1.0]
        ratio = base * max(octaves, key=lambda o: float(prior.pdf(centre * o)))
    # rivals: the other levels that are not this one's octave (2/3 and 4/3 are each other's octave)
    chosen = max(scores[best], 0.0)
    rivals = [
        max(float(scores[i]), 0.0)
        for i, r in enumerate(LEVEL_RATIOS)
        if not np.isclose(np.log2(r / base) % 1.0, 0.0, atol=1e-6)
        and not np.isclose(np.log2(r / base) % 1.0, 1.0, atol=1e-6)
    ]
    rival = max(rivals) if rivals else 0.0
    confidence = chosen / (chosen + rival) if chosen + rival > 0 else 0.0
    return ratio, round(float(confidence), 4)


def _fill_gaps(frames: Array, window: int = 8) -> Array:
    """Beats added, evenly, where an interval spans about a whole number (>= 2) of the local period
    (the median interval of the ``window`` intervals around it): the dynamic programme sometimes
    skips a beat where the tempo moves faster than its smoothed estimate (they are then refined
    to onsets like the others)."""
    ibi = np.diff(frames)
    if ibi.size < 3:
        return frames
    out = [frames[:1]]
    for i, d in enumerate(ibi):
        lo, hi = max(0, i - window // 2), min(ibi.size, i + window // 2 + 1)
        local = float(np.median(ibi[lo:hi]))
        n = int(round(d / local))
        if n >= 2 and abs(d / n - local) < 0.2 * local:
            out.append(frames[i] + d * np.arange(1, n) / n)
        out.append(frames[i + 1 : i + 2])
    return np.concatenate(out)


def _refine(oenv: npt.NDArray[Any], frames: Array) -> Array:
    """Each beat frame moved to the onset-envelope peak within ``REFINE`` of the local period,
    at sub-frame precision."""
    env = np.asarray(oenv, dtype=np.float64)
    period = np.diff(frames)
    period = np.concatenate((period[:1], period)) if period.size else np.array([env.size / 4.0])
    out = frames.copy()
    for i, (f, p) in enumerate(zip(frames, period, strict=True)):
        r = max(1, int(round(REFINE * p)))
        lo, hi = max(0, int(f) - r), min(env.size, int(f) + r + 1)
        k = lo + int(np.argmax(env[lo:hi]))
        if 0 < k < env.size - 1:
            a, b, c = env[k - 1], env[k], env[k + 1]
            den = a - 2 * b + c
            out[i] = k + (0.5 * (a - c) / den if den < 0 else 0.0)
        else:
            out[i] = k
    return out


def _downbeat(y: Array, beats: Array, meter: int) -> int | None:
    """Index of the first downbeat (module doc), None when no bar phase stands out."""
    import librosa

    if meter < 2 or beats.size < 2 * meter:
        return None
    spec = np.abs(librosa.stft(y.astype(np.float32), n_fft=2048, hop_length=HOP)) ** 2
    low = spec[: int(np.ceil(DOWNBEAT_MAX_HZ * 2048 / SR)) + 1].sum(axis=0)  # power below ~150 Hz
    idx = np.clip(np.rint(beats * SR / HOP).astype(np.intp), 0, low.size - 1)
    reach = max(1, int(round(0.06 * SR / HOP)))  # the hit's first 60 ms
    strength = np.max([low[np.clip(idx + d, 0, low.size - 1)] for d in range(reach + 1)], axis=0)
    per_phase = np.array([np.median(strength[p::meter]) for p in range(meter)])
    order = np.argsort(per_phase)[::-1]
    if per_phase[order[0]] < DOWNBEAT_MARGIN * max(per_phase[order[1]], 1e-12):
        return None
    return int(order[0])


def audio_beats(data: bytes, tempo_bpm: float | None = None, meter: int = 4) -> AudioBeats:
    """Decode a recording's bytes and track its beats (:func:`decode`, :func:`track_beats`)."""
    y, duration = decode(data)
    found = track_beats(y, tempo_bpm, meter)
    return AudioBeats(found.beats_s, found.tempo_bpm, found.downbeat, duration, found.tempo_confidence)
