"""Bundled samples (``sample:NAME``) in the store: what the API does when a spec or a request names
one instead of an upload.

A sample is stored like an upload of its file (content-addressed, so once), which keeps every job
reading bytes the store holds (the same path as any other input).
"""

from __future__ import annotations

from motion.samples import SAMPLE_UNITS, is_clip_sample, sample_name, sample_path
from schemas import ClipInfo

from .store import Store


def store_sample(store: Store, ref: str) -> tuple[str, ClipInfo | None] | None:
    """The upload id of the bundled sample ``ref`` names (``sample:NAME``), stored on first use,
    with its :class:`ClipInfo` when it is a clip (in the unit the catalogue declares,
    :data:`motion.samples.SAMPLE_UNITS`) (None for other files, e.g. the MIDI song); None
    when ``ref`` names no sample. Raises :class:`motion.MotionError` for an unknown sample name."""
    name = sample_name(ref)
    if name is None:
        return None
    path = sample_path(name)
    data = path.read_bytes()
    if is_clip_sample(name):
        info = store.put_clip(path.name, data, units=SAMPLE_UNITS.get(name))
        return info.id, info
    return store.put_file(path.name, data).id, None
