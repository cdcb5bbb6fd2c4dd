"""The control engine's two tiers (``engines.control.tier``): the compiled secondary kernels and
their NumPy twins give the same bits, a process that was not warmed runs the twins (compiling only
the forward pass), and a warmed one (``segue warm``'s stamp, or :func:`tier.use_compiled`) runs
the kernels."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import TypeVar

import numpy as np
import pytest

from engines.control import tier
from engines.control.dp import cost_to_go, interpretation, legal_cells, retime, stretched_templates
from tests.engines.test_control_dp import RATE, many_instances
from tests.engines.test_control_retime import assert_same, random_problem, ref_retime

ROOT = Path(__file__).resolve().parents[2]
GUARD_S = 120
T = TypeVar("T")


NO_STAMP = Path("/nonexistent/segue-warm-stamp")


@pytest.fixture
def twins(monkeypatch: pytest.MonkeyPatch) -> None:
    """Run the NumPy twins in this test, whatever the cache holds."""
    monkeypatch.setitem(tier._state, "ready", False)
    monkeypatch.setattr(tier, "stamp", lambda: NO_STAMP)


def both(fn: Callable[[], T]) -> tuple[T, T]:
    """``fn()`` run with the twins, then with the kernels: the two results."""

    def run(ready: bool) -> T:
        with pytest.MonkeyPatch.context() as mp:
            mp.setitem(tier._state, "ready", ready)
            mp.setattr(tier, "stamp", lambda: NO_STAMP)
            return fn()

    return run(False), run(True)


@pytest.mark.parametrize("context", [0, 2])
@pytest.mark.parametrize("seed", [0, 3, 5])
def test_interpretation_and_cost_to_go_are_the_same_bits_in_both_tiers(seed: int, context: int) -> None:
    inst, x = many_instances(seed)
    ci, cd = legal_cells(inst.length / inst.fps, RATE, 0.1, None)
    twin, kern = both(lambda: interpretation(x, inst, ci, cd, RATE, context))
    for name in ("DT", "CT", "ST", "sum_a", "cs"):
        assert np.array_equal(getattr(twin, name), getattr(kern, name)), name
        assert getattr(twin, name).tobytes() == getattr(kern, name).tobytes(), name
    twin.D[3, :] = np.inf  # an illegal cell
    kern.D[3, :] = np.inf
    f_twin, f_kern = both(lambda: cost_to_go(twin.D, cd))
    assert f_twin.tobytes() == f_kern.tobytes()
    assert np.isfinite(f_twin[0])


def test_template_sampling_is_the_same_bits_in_both_tiers() -> None:
    inst, _ = many_instances(2)
    which = np.arange(inst.count, dtype=np.intp)
    for context in (0, 3):
        a, b = both(partial(stretched_templates, inst, which, 5, RATE, context))
        assert a.tobytes() == b.tobytes()


@pytest.mark.parametrize("seed", range(0, 40, 3))
def test_retime_is_the_reference_in_both_tiers(seed: int) -> None:
    pb = random_problem(seed)
    rng = pb["rng"]
    context = int(rng.integers(0, 4)) if seed % 2 else 0
    k = float(rng.uniform(0.0, 2.0))
    args = (pb["x"], pb["inst"], pb["seq"], pb["coarse"], k, 30.0, 0.15, None, int(rng.integers(1, 5)))
    want = ref_retime(*args, context=context)
    twin, kern = both(lambda: retime(*args, context=context))
    assert_same(twin, want)
    assert_same(kern, want)


def test_a_control_request_gives_the_same_bytes_in_both_tiers() -> None:
    """The warm-up's salsa request (bundled samples: a database of one pair, a held-back leader's
    stretch as control) gives the same motion, score and provenance with the twins and the kernels."""
    from engines.base import CollectingEmitter, Run
    from engines.control.warm import salsa_request

    def run() -> list[tuple[bytes, float, list[tuple[str, int]]]]:
        engine, request = salsa_request()
        emit = CollectingEmitter()
        engine.search(request, Run(request.budget_s, emit=emit))
        out = []
        for sol in emit.solutions:
            m = sol.motion
            data = m.root_positions.tobytes() + m.rotations.tobytes() + m.joint_translations.tobytes()
            out.append((data, sol.score, sol.provenance))
        return out

    twin, kern = both(run)
    assert twin and twin == kern


def test_an_unwarmed_process_compiles_only_the_forward_path(tmp_path: Path) -> None:
    """A control request in a process whose cache was not warmed runs (so compiles, on a fresh
    cache) the forward pass and the motion sampling kernel, and none of the secondary kernels nor
    the FK kernel; after :func:`tier.use_compiled` it runs every one."""
    script = """
import json, sys
from pathlib import Path
from engines.control import kernels, tier
tier.stamp = lambda: Path("/nonexistent/segue-warm-stamp")
if sys.argv[1] == "compiled":
    tier.use_compiled()
from engines.base import Run
from engines.control.warm import salsa_request
engine, request = salsa_request()
engine.search(request, Run(request.budget_s))
names = ["forward", "cost_to_go", "state_alignments", "retime_chain", "sample_frames",
         "duration_operands", "residual_block"]
from motion import compiled
counts = {n: len(getattr(kernels, n).overloads) for n in names}
counts["_fk_kernel"] = len(compiled._fk_kernel.overloads)
print(json.dumps(counts))
"""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}  # numba's cache as configured: loading is enough
    ran = {}
    for mode in ("twins", "compiled"):
        out = subprocess.run(
            [sys.executable, "-c", script, mode],
            cwd=tmp_path,
            env=env,
            capture_output=True,
            text=True,
            timeout=GUARD_S,
            check=True,
        )
        ran[mode] = json.loads(out.stdout.strip().splitlines()[-1])
    secondary = ["cost_to_go", "state_alignments", "retime_chain", "sample_frames"]
    secondary += ["duration_operands", "residual_block", "_fk_kernel"]
    assert ran["twins"]["forward"] == 1
    assert all(ran["twins"][n] == 0 for n in secondary), ran["twins"]
    assert all(ran["compiled"][n] == 1 for n in ["forward", *secondary]), ran["compiled"]


def test_the_warm_stamp_switches_a_process_to_the_kernels(
    tmp_path: Path, twins: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    assert not tier.compiled_ready()
    stamp = tmp_path / "segue-warm-test"
    monkeypatch.setattr(tier, "stamp", lambda: stamp)
    assert not tier.compiled_ready()
    stamp.write_text("1\n")
    assert tier.compiled_ready()
