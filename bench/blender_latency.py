"""How soon the first solution shows on the character after pressing Generate in Blender, on a warm
local service. Prints JSON.

Starts ``segue serve`` on a free port (its own data folder), builds the README's graph database
(four CMU walks and a salsa dance), writes the add-on with ``segue blender-addon`` and runs Blender
(``bpy`` from PyPI: ``$SEGUE_BPY_PYTHON``, default ``~/.cache/segue/bpy-venv/bin/python``) on a
skinned test character (tests/integrations/bpy_scripts/rigs.py) with two goal empties. One
warm-up Generate warms the service (the database loaded in its engine processes, the
retargeting code imported) and uploads the rig; then each run moves the second goal and presses
Generate (``bpy.ops.segue.generate(scene_goals=True)``, followed to the end) and times, from the
press: the scene read (and the rig's export when its state changed), the submission answered,
the first ``solution`` event seen by the long poll, its result bound to the rig downloaded and
parsed, and keyed on the armature (the action the viewport shows). ``first_solution_s`` is that
last figure. The first press with a new rig state (export + upload of the rig's GLB) is reported
apart (``cold``).

    python bench/blender_latency.py [--runs N]
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx

REPO = Path(__file__).resolve().parents[1]
SEGUE = Path(sys.executable).with_name("segue")
SPEC = {
    "kind": "graph", "fps": 30, "tau": 1.0, "name": "walks",
    "clips": [{"bvh": f"sample:{n}"}
              for n in ("walk", "walk-05-01", "walk-10-04", "walk-12-02", "salsa-leader-02")],
}  # fmt: skip

BLENDER_SCRIPT = r"""
import json, sys, time
sys.path.insert(0, {rigs!r})
import bpy
import rigs
cfg = json.loads({cfg!r})
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.extensions.package_install_files(filepath=cfg["zip"], repo="user_default", enable_on_install=True)
state = next(m for k, m in sys.modules.items() if k.endswith("segue_blender.state"))
sc = bpy.context.scene
sc.render.fps = 24
sc.frame_start, sc.frame_end = 1, 97
char = rigs.courier()
start = bpy.data.objects.new("Start", None); start.location = (1.0, -0.5, 0.0); start["segue_frame"] = 1
end = bpy.data.objects.new("End", None); end.location = (3.5, -1.5, 0.0); end["segue_frame"] = 97
for e in (start, end):
    sc.collection.objects.link(e)
bpy.context.view_layer.objects.active = char
char.select_set(True)
bpy.ops.segue.connect(url=cfg["url"])
runs = []
for k in range(cfg["runs"] + 2):
    if k == 1:  # a new rig state: exported and uploaded on this press
        char.location.x += 0.25
    end.location.y = -1.5 - 0.1 * k
    assert bpy.ops.segue.generate(database="walks", scene_goals=True, wait=True) == {{"FINISHED"}}
    v = state.SESSION.job
    runs.append({{"first_solution_s": v.first_solution_s, "solutions": v.solutions, "ok": v.ok, **v.timings}})
print("RUNS" + json.dumps(runs))
"""


def free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=10, help="warm presses measured (default 10)")
    args = ap.parse_args()
    bpy_python = os.environ.get("SEGUE_BPY_PYTHON") or str(Path.home() / ".cache/segue/bpy-venv/bin/python")
    with tempfile.TemporaryDirectory() as tmp:
        port = free_port()
        log = open(Path(tmp) / "serve.log", "wb")  # noqa: SIM115 (open for the server's life)
        cmd = [
            str(SEGUE),
            "serve",
            "--port",
            str(port),
            "--data",
            str(Path(tmp) / "data"),
            "--log-level",
            "warning",
        ]
        serve = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT)
        url = f"http://127.0.0.1:{port}"
        try:
            deadline = time.monotonic() + 120
            while True:
                try:
                    if httpx.get(f"{url}/healthz", timeout=1).status_code == 200:
                        break
                except httpx.TransportError:
                    pass
                if time.monotonic() > deadline:
                    raise SystemExit("segue serve did not start")
                time.sleep(0.1)
            sys.path.insert(0, str(REPO))
            from service.client import SegueClient

            with SegueClient(url, timeout=120) as client:
                client.build_database(SPEC, timeout=600)
            zip_path = Path(tmp) / "segue_blender.zip"
            subprocess.run(
                [str(SEGUE), "blender-addon", "--out", str(zip_path)], check=True, capture_output=True
            )
            cfg = json.dumps({"zip": str(zip_path), "url": url, "runs": args.runs})
            script = Path(tmp) / "bench.py"
            rigs = str(REPO / "tests" / "integrations" / "bpy_scripts")
            script.write_text(BLENDER_SCRIPT.format(rigs=rigs, cfg=cfg))
            env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
            env["BLENDER_USER_RESOURCES"] = str(Path(tmp) / "blender-user")
            res = subprocess.run(
                [bpy_python, str(script)], capture_output=True, text=True, env=env, timeout=1800
            )
            line = next((x for x in res.stdout.splitlines() if x.startswith("RUNS")), None)
            if line is None:
                raise SystemExit(f"Blender failed:\n{res.stdout[-3000:]}\n{res.stderr[-3000:]}")
            runs = json.loads(line[4:])
        finally:
            serve.send_signal(signal.SIGINT)
            serve.wait(timeout=30)
    warm = runs[2:]
    keys = ("scene_s", "submitted_s", "solution_seen_s", "prepared_s", "first_solution_s")

    def stat(rs: list[dict[str, float]], key: str) -> dict[str, float]:
        xs = sorted(float(r[key]) for r in rs if r.get(key) is not None)
        return {"p50": round(statistics.median(xs), 3), "max": round(xs[-1], 3)}

    out = {
        "runs": len(warm),
        "warm": {k: stat(warm, k) for k in keys}
        | {"keying_s": stat(warm, "keying_s"), "download_s": stat(warm, "download_s")},
        "cold_rig": {
            k: round(float(runs[1][k]), 3)
            for k in (*keys, "uploads_s", "download_s")
            if runs[1].get(k) is not None
        },
        "first_solution_under_2s": sum(float(r["first_solution_s"]) < 2.0 for r in warm),
        "solutions_per_job_p50": statistics.median(r["solutions"] for r in warm),
        "load_avg_1min": round(os.getloadavg()[0], 2),
        "cpus": os.cpu_count(),
    }
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
