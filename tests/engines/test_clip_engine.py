"""The motion library and the clip engine."""

from __future__ import annotations

import numpy as np
import pytest

from engines.base import EngineError, Run
from engines.clip import ClipEngine
from engines.library import ClipInput, build_library, library_from_arrays, library_to_arrays
from engines.registry import parse_job_request
from motion import MotionError
from motion.ground import heading
from motion.mirror import mirror_map
from motion.samples import sample_path
from tests.engines.emitters import Collect


@pytest.fixture(scope="module")
def library():  # type: ignore[no-untyped-def]
    leader = sample_path("salsa-leader").read_bytes()
    follower = sample_path("salsa-follower").read_bytes()
    return build_library([ClipInput("leader", leader), ClipInput("follower", follower)], fps=30)


def test_library_resamples_converts_and_round_trips(library) -> None:  # type: ignore[no-untyped-def]
    assert library.names == ("leader", "follower")
    assert library.fps == 30.0 and all(m.units == "m" for m in library.motions)
    assert library.motions[0].num_frames == 561  # 2242 frames at 120 fps -> 18.675 s at 30 fps
    back = library_from_arrays(library_to_arrays(library))
    np.testing.assert_allclose(back.motions[1].global_positions(), library.motions[1].global_positions())


def test_library_errors_name_the_clip() -> None:
    walk = sample_path("walk").read_bytes()
    other = sample_path("start-walk-stop").read_bytes()
    with pytest.raises(MotionError, match="'b' has a different joint hierarchy"):
        build_library([ClipInput("a", walk), ClipInput("b", other)])
    with pytest.raises(MotionError, match="repeated: a"):
        build_library([ClipInput("a", walk), ClipInput("a", walk)])
    with pytest.raises(MotionError, match="clip 'bad'"):
        build_library([ClipInput("bad", b"HIERARCHY\nROOT x\n{\n")])


def test_clip_engine_excerpt_mirror_and_placement(library) -> None:  # type: ignore[no-untyped-def]
    engine = ClipEngine(library, library_to_arrays(library))
    out = Collect()
    req = parse_job_request(
        {
            "engine": "clip",
            "clip": "follower",
            "start": 30,
            "end": 90,
            "mirror": True,
            "position": [2.0, -1.0],
            "heading_deg": 45,
        }
    )
    engine.search(req, Run(1.0, emit=out))
    (sol,) = out.solutions
    assert sol.motion.num_frames == 60
    assert sol.provenance[0] == ("follower", 30) and sol.provenance[-1] == ("follower", 89)
    np.testing.assert_allclose(sol.motion.root_positions[0, [0, 2]], [2.0, -1.0], atol=1e-9)
    assert np.degrees(heading(sol.motion)[0]) == pytest.approx(45.0, abs=1e-6)
    # mirroring swaps left and right; the rigid placement keeps every joint's height
    src = library.clip("follower").slice(30, 90)
    partner, _ = mirror_map(src.skeleton.names)
    np.testing.assert_allclose(
        sol.motion.global_positions()[..., 1], src.global_positions()[:, partner, 1], atol=1e-9
    )


def test_clip_engine_bad_requests(library) -> None:  # type: ignore[no-untyped-def]
    engine = ClipEngine(library, {})
    with pytest.raises(EngineError, match="no clip named 'x'"):
        engine.search(parse_job_request({"engine": "clip", "clip": "x"}), Run(1.0, emit=Collect()))
    with pytest.raises(EngineError, match="outside clip"):
        engine.search(
            parse_job_request({"engine": "clip", "clip": "leader", "start": 5000}), Run(1.0, emit=Collect())
        )
