"""Bundled samples (CMU motion capture as gzip-compressed BVH, and one MIDI song) so that every
engine runs without ../shared.

Anywhere Segue reads a clip or an input file by path (the CLI, database specs, request files, HTTP
requests) ``sample:NAME`` names a bundled sample instead. See ``SAMPLES.md`` beside this file for the
source and licence of each one.
"""

from __future__ import annotations

from pathlib import Path

from ..errors import MotionError

_DIR = Path(__file__).resolve().parent

SAMPLE_PREFIX = "sample:"
"""How a path names a bundled sample: ``sample:walk``."""

SAMPLES: dict[str, str] = {
    "salsa-leader": "60_01_salsa_leader.bvh.gz",
    "salsa-follower": "61_01_salsa_follower.bvh.gz",
    "walk": "07_01_walk_daz.bvh.gz",
    "start-walk-stop": "131_01_start_walk_stop.bvh.gz",
    "salsa-leader-02": "60_02_salsa_leader_30fps.bvh.gz",
    "salsa-follower-02": "61_02_salsa_follower_30fps.bvh.gz",
    "salsa-leader-04": "60_04_salsa_leader_30fps.bvh.gz",
    "salsa-follower-04": "61_04_salsa_follower_30fps.bvh.gz",
    "salsa-leader-05": "60_05_salsa_leader_30fps.bvh.gz",
    "salsa-follower-05": "61_05_salsa_follower_30fps.bvh.gz",
    "salsa-leader-12": "60_12_salsa_leader_30fps.bvh.gz",
    "walk-05-01": "05_01_walk_daz_30fps.bvh.gz",
    "walk-10-04": "10_04_walk_daz_30fps.bvh.gz",
    "walk-12-02": "12_02_walk_daz_30fps.bvh.gz",
    "run-09-01": "09_01_run_daz_30fps.bvh.gz",
    "run-09-02": "09_02_run_daz_30fps.bvh.gz",
    "run-09-03": "09_03_run_daz_30fps.bvh.gz",
    "run-09-04": "09_04_run_daz_30fps.bvh.gz",
    "jump-13-11": "13_11_jump_daz_30fps.bvh.gz",
    "jump-13-32": "13_32_jump_daz_30fps.bvh.gz",
    "song": "song_104_116bpm.mid",
}
"""Sample name -> file in this folder. Every ``.bvh.gz`` but ``start-walk-stop`` shares the 43-joint
CMU skeleton (hip, abdomen, chest, ...), so any of them can share one database."""

SAMPLE_UNITS: dict[str, str] = {name: "cmu-scaled" for name in SAMPLES if name.startswith("salsa-")}
"""The length unit the catalogue declares for a sample clip (the others are guessed from their
height, correctly: ``cm`` and ``cmu``). The salsa samples are CMU "_scaled" files whose unit is
1.28 m (:data:`motion.units.METRES_PER_UNIT`, ``cmu-scaled``): too close to the metre to guess, so
read as guessed they would be 1.15 m dancers instead of 1.46 m. A unit given explicitly wins."""


def sample_path(name: str) -> Path:
    """Path of a bundled sample by name (see :data:`SAMPLES`)."""
    try:
        return _DIR / SAMPLES[name]
    except KeyError:
        raise MotionError(f"no bundled sample {name!r}; available: {', '.join(SAMPLES)}") from None


def is_clip_sample(name: str) -> bool:
    """True when the sample is a motion clip (a ``.bvh.gz``), False for other files (MIDI)."""
    return SAMPLES.get(name, "").endswith(".bvh.gz")


def sample_name(ref: str | Path) -> str | None:
    """The sample a reference names (``"sample:walk"`` -> ``"walk"``), or None for any other path.

    Raises :class:`MotionError` listing the samples for ``sample:`` and an unknown name."""
    if not isinstance(ref, str) or not ref.startswith(SAMPLE_PREFIX):
        return None
    name = ref[len(SAMPLE_PREFIX) :]
    sample_path(name)  # unknown names fail here, naming the available ones
    return name


def resolve_path(ref: str | Path, base: Path | None = None) -> Path:
    """The file a path reference names: a bundled sample for ``sample:NAME``, ``base / ref`` for a
    relative path when ``base`` is given (a spec's or a request's folder), else ``ref`` itself."""
    name = sample_name(ref)
    if name is not None:
        return sample_path(name)
    path = Path(ref)
    if base is not None and not path.is_absolute():
        return base / path
    return path


def sample_of_path(path: str | Path) -> str | None:
    """The sample a path is the bundled file of (``sample:NAME`` or this folder's file), else None."""
    name = sample_name(path) if isinstance(path, str) else None
    if name is not None:
        return name
    p = Path(path)
    if p.parent.resolve() != _DIR:
        return None
    return next((n for n, f in SAMPLES.items() if f == p.name), None)


def declared_units(path: str | Path) -> str | None:
    """The unit the catalogue declares (:data:`SAMPLE_UNITS`) for the clip ``path`` names
    (``sample:NAME`` or a bundled sample's file), None for any other file (read as guessed)."""
    name = sample_of_path(path)
    return SAMPLE_UNITS.get(name) if name is not None else None


def upload_units(file_name: str, data: bytes) -> str | None:
    """The declared unit of an upload that *is* a bundled sample: named as its file (the browser
    uploads ``60_01_salsa_leader.bvh.gz`` from ``GET /samples``) and byte for byte the same;
    None for any other upload."""
    name = next((n for n, f in SAMPLES.items() if f == Path(file_name).name), None)
    if name is None or name not in SAMPLE_UNITS:
        return None
    return SAMPLE_UNITS[name] if sample_path(name).read_bytes() == data else None
