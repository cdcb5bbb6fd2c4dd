"""Process tuning: the allocator settings and one BLAS thread, applied in a fresh process."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

SCRIPT = """
import json
from threadpoolctl import threadpool_info
from motion.allocator import tune_process
before = [p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"]
tune_process()
after = [p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"]
print(json.dumps({"before": before, "after": after}))
"""


def test_tune_process_leaves_one_blas_thread() -> None:
    pytest.importorskip("threadpoolctl")
    out = subprocess.run(
        [sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=120, check=True
    )
    threads = json.loads(out.stdout.strip().splitlines()[-1])
    if not threads["before"]:
        pytest.skip("numpy reports no BLAS thread pool here")
    assert threads["after"] and set(threads["after"]) == {1}
