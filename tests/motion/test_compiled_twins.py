""":func:`motion.compiled.fast_fk` gives the same bits with its NumPy twin (a process that was not
warmed) and with the compiled kernel (after ``segue warm``, :func:`motion.jitcache.compiled_ready`)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from motion import jitcache, parse_bvh
from motion.compiled import fast_fk
from motion.samples import resolve_path


@pytest.mark.parametrize("ref", ["sample:salsa-leader-02", "sample:walk"])
def test_fast_fk_is_the_same_bits_in_both_tiers(ref: str, monkeypatch: pytest.MonkeyPatch) -> None:
    motion = parse_bvh(resolve_path(ref).read_bytes(), source=ref).slice(0, 200)
    rng = np.random.default_rng(0)
    q = rng.normal(size=motion.rotations.shape)
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    for m in (motion, replace(motion, rotations=q)):
        monkeypatch.setitem(jitcache._ready, "compiled", False)
        twin = fast_fk(m)
        monkeypatch.setitem(jitcache._ready, "compiled", True)
        kernel = fast_fk(m)
        assert twin[0].tobytes() == kernel[0].tobytes()
        assert twin[1].tobytes() == kernel[1].tobytes()
        assert np.allclose(twin[0], m.fk()[0], atol=1e-9)
