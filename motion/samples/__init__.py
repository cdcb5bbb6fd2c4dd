"""Bundled sample clips (CMU motion capture, gzip-compressed BVH) so Segue works without ../shared.

See ``SAMPLES.md`` beside this file for the source and licence of each clip.
"""

from __future__ import annotations

from pathlib import Path

from ..errors import MotionError

_DIR = Path(__file__).resolve().parent

SAMPLES: dict[str, str] = {
    "salsa-leader": "60_01_salsa_leader.bvh.gz",
    "salsa-follower": "61_01_salsa_follower.bvh.gz",
    "walk": "07_01_walk_daz.bvh.gz",
    "start-walk-stop": "131_01_start_walk_stop.bvh.gz",
}


def sample_path(name: str) -> Path:
    """Path of a bundled sample by name (see :data:`SAMPLES`)."""
    try:
        return _DIR / SAMPLES[name]
    except KeyError:
        raise MotionError(f"no bundled sample {name!r}; available: {', '.join(SAMPLES)}") from None


def sample_names() -> list[str]:
    return list(SAMPLES)
