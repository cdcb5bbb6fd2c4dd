"""The add-on's operators (``bpy.ops.segue.*``): the script API and the panels' buttons."""

from __future__ import annotations

import json
import math
import os
import queue
import re
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, StringProperty

from . import authoring, binding, gltf, scene
from .axes import SegueFrame
from .client import SegueClient, SegueError
from .jobs import JobRunner, Message
from .local_service import LocalService
from .roles import RoleError
from .state import SESSION, GoalResult, JobView

WAIT_GUARD_S = 600.0
"""``wait=True``: the longest a script waits for a job or a build (a hang guard)."""
DRAIN_S = 0.05
"""How often the UI takes what the job's thread has received (seconds)."""


def _prefs(context: bpy.types.Context) -> Any:
    addon = context.preferences.addons.get(__package__ or "")
    return addon.preferences if addon is not None else None


def _settings(context: bpy.types.Context) -> Any:
    return context.scene.segue


def _fail(op: bpy.types.Operator, message: str) -> set[str]:
    SESSION.error = message
    op.report({"ERROR"}, message)
    return {"CANCELLED"}


def _client() -> SegueClient:
    if SESSION.client is None:
        raise SegueError(
            0, "not_connected", "not connected to Segue: connect first (Segue panel or bpy.ops.segue.connect)"
        )
    return SESSION.client


def _is_local(url: str) -> bool:
    host = re.sub(r"^https?://", "", url).split("/")[0].rsplit(":", 1)[0].strip("[]")
    return host in ("127.0.0.1", "localhost", "::1")


def refresh_lists() -> None:
    """The server's clips and databases, into the session."""
    client = _client()
    SESSION.clips = client.clips()
    SESSION.databases = client.databases()


def connect(url: str, token: str | None) -> dict[str, Any]:
    """Connect the session to ``url``; the server's health."""
    if not _is_local(url) and not getattr(bpy.app, "online_access", True):
        raise SegueError(0, "offline", "Blender's online access is off (Preferences > System > Network): "
                         "allow it to reach a remote Segue server")  # fmt: skip
    client = SegueClient(url, token)
    health = client.health()
    if not health.get("ok"):
        raise SegueError(503, "unhealthy", f"Segue at {client.url} cannot serve: {health}")
    if SESSION.client is not None and SESSION.client.url != client.url:
        SESSION.client.close()
    SESSION.client = client
    SESSION.health = health
    refresh_lists()
    SESSION.status = f"connected to {client.url}"
    SESSION.error = ""
    return health


# -- connection -----------------------------------------------------------------------------------
class SEGUE_OT_connect(bpy.types.Operator):
    """Connect to a Segue service (its URL and, when it sets tokens, a token)"""

    bl_idname = "segue.connect"
    bl_label = "Connect"
    bl_options = {"REGISTER"}

    url: StringProperty(
        name="URL", description="the service, e.g. http://127.0.0.1:8000 (default: the panel's)"
    )
    token: StringProperty(
        name="Token", description="bearer token (servers with SEGUE_API_TOKENS)", subtype="PASSWORD"
    )

    def execute(self, context: bpy.types.Context) -> set[str]:
        settings = _settings(context)
        url = self.url or settings.url
        token = self.token or context.window_manager.segue_token or None
        try:
            health = connect(url, token)
        except SegueError as exc:
            SESSION.status = "not connected"
            return _fail(self, exc.message)
        settings.url = SESSION.url
        backend = health.get("backend", {})
        self.report({"INFO"}, f"Segue at {SESSION.url}: {backend.get('backend', '?')} backend, "
                    f"{len(SESSION.databases)} databases, {len(SESSION.clips)} clips")  # fmt: skip
        return {"FINISHED"}


class SEGUE_OT_disconnect(bpy.types.Operator):
    """Forget the Segue service (a local one keeps running until Blender exits or it is stopped)"""

    bl_idname = "segue.disconnect"
    bl_label = "Disconnect"

    def execute(self, context: bpy.types.Context) -> set[str]:
        if SESSION.client is not None:
            SESSION.client.close()
        SESSION.client = None
        SESSION.status = "not connected"
        SESSION.clips, SESSION.databases = [], []
        return {"FINISHED"}


class SEGUE_OT_start_local(bpy.types.Operator):
    """Start `segue serve` from the add-on preferences' executable on a free port and connect to it"""

    bl_idname = "segue.start_local"
    bl_label = "Start local service"

    def execute(self, context: bpy.types.Context) -> set[str]:
        prefs = _prefs(context)
        exe = (prefs.segue_executable if prefs else "") or os.environ.get("SEGUE_EXECUTABLE", "")
        if not exe:
            return _fail(self, "set the path of a `segue` executable in the add-on's preferences")
        data = (prefs.data_dir if prefs else "") or bpy.utils.user_resource(
            "DATAFILES", path="segue", create=True
        )
        imports = [d.strip() for d in ((prefs.import_dirs if prefs else "") or "").split(";") if d.strip()]
        if SESSION.local is not None and SESSION.local.running:
            SESSION.local.stop()
        SESSION.local = LocalService(bpy.path.abspath(exe), bpy.path.abspath(data), imports)
        try:
            url = SESSION.local.start()
            connect(url, None)
        except SegueError as exc:
            return _fail(self, exc.message)
        _settings(context).url = url
        self.report({"INFO"}, f"local Segue service at {url} (data {SESSION.local.data_dir})")
        return {"FINISHED"}


class SEGUE_OT_stop_local(bpy.types.Operator):
    """Stop the local Segue service this Blender started"""

    bl_idname = "segue.stop_local"
    bl_label = "Stop local service"

    def execute(self, context: bpy.types.Context) -> set[str]:
        if SESSION.local is not None:
            if SESSION.client is not None and SESSION.client.url == SESSION.local.url:
                SESSION.client.close()
                SESSION.client = None
                SESSION.status = "not connected"
            SESSION.local.stop()
            SESSION.local = None
        return {"FINISHED"}


class SEGUE_OT_refresh(bpy.types.Operator):
    """List the service's clips and databases again"""

    bl_idname = "segue.refresh"
    bl_label = "Refresh"

    def execute(self, context: bpy.types.Context) -> set[str]:
        try:
            refresh_lists()
        except SegueError as exc:
            return _fail(self, exc.message)
        return {"FINISHED"}


# -- the rig --------------------------------------------------------------------------------------
def _armature(context: bpy.types.Context, name: str = "") -> bpy.types.Object:
    obj = bpy.data.objects.get(name) if name else context.active_object
    if obj is None or obj.type != "ARMATURE":
        raise RoleError(f"{'no armature ' + repr(name) if name else 'the active object is not an armature'}")
    return obj


class SEGUE_OT_detect_roles(bpy.types.Operator):
    """Find which bones are the hips, legs, feet, arms and head (by the skeleton's shape and names)"""

    bl_idname = "segue.detect_roles"
    bl_label = "Detect roles"
    bl_options = {"REGISTER", "UNDO"}

    armature: StringProperty(name="Armature", description="default: the active object")

    def execute(self, context: bpy.types.Context) -> set[str]:
        try:
            obj = _armature(context, self.armature)
        except RoleError as exc:
            return _fail(self, str(exc))
        found = scene.detect_roles(obj)
        missing = [
            r
            for r in (
                "Hips",
                "LeftUpperLeg",
                "LeftLowerLeg",
                "LeftFoot",
                "RightUpperLeg",
                "RightLowerLeg",
                "RightFoot",
            )
            if r not in found
        ]
        if missing:
            self.report(
                {"WARNING"}, f"{obj.name}: no bone found for {', '.join(missing)}: set them in the Rig panel"
            )
        else:
            self.report({"INFO"}, f"{obj.name}: {len(found)} roles found")
        return {"FINISHED"}


# -- clips and databases --------------------------------------------------------------------------
def _clip_name(obj: bpy.types.Object, action: bpy.types.Action) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", f"{obj.name}-{action.name}").strip("_") + ".bvh"


class SEGUE_OT_upload_action(bpy.types.Operator):
    """Upload the active armature's action (or all its actions) as Segue clips (BVH); the action's
    pose markers (``walk``, ``!jump``) become the clip's labels in an annotated database built from
    it"""

    bl_idname = "segue.upload_action"
    bl_label = "Upload action"

    action: StringProperty(name="Action", description="default: the armature's current action")
    all_actions: BoolProperty(name="All actions", description="every action made for this armature")
    name: StringProperty(name="Clip name", description="default: ARMATURE-ACTION.bvh")
    armature: StringProperty(name="Armature", description="default: the active object")
    keep_names: BoolProperty(
        name="Keep bone names", description="upload the bones under their own names (no roles)"
    )

    def execute(self, context: bpy.types.Context) -> set[str]:
        try:
            client = _client()
            obj = _armature(context, self.armature)
            if self.action:
                actions = [bpy.data.actions[self.action]]
            elif self.all_actions:
                actions = [a for a in bpy.data.actions if not a.get("segue_job") and _drives(a, obj)]
            else:
                ad = obj.animation_data
                if ad is None or ad.action is None:
                    raise RoleError(f"{obj.name} has no action to upload")
                actions = [ad.action]
            names = []
            for act in actions:
                text = scene.export_clip(obj, act, keep_names=self.keep_names)
                name = self.name if (self.name and len(actions) == 1) else _clip_name(obj, act)
                info = client.upload_clip(text.encode(), name, units="m")
                names.append(str(info["name"]))
                first, last = (round(f) for f in act.frame_range)
                markers = [authoring.Marker(m.name, m.frame) for m in act.pose_markers]
                labels = authoring.label_ranges(markers, first, last)
                if labels:
                    SESSION.clip_labels[str(info["name"])] = labels
                if info["name"] not in SESSION.uploaded:
                    SESSION.uploaded.append(str(info["name"]))
            refresh_lists()
        except KeyError as exc:
            return _fail(self, f"no action {exc}")
        except (SegueError, RoleError, gltf.GltfError) as exc:
            return _fail(self, getattr(exc, "message", str(exc)))
        self.report({"INFO"}, f"uploaded {', '.join(names)}")
        return {"FINISHED"}


def _drives(action: bpy.types.Action, obj: bpy.types.Object) -> bool:
    bones = {b.name for b in obj.data.bones}
    for fc in _fcurves_of(action):
        m = re.match(r'pose\.bones\["(.+?)"\]', fc.data_path)
        if m and m.group(1) in bones:
            return True
    return False


def _fcurves_of(action: bpy.types.Action) -> list[Any]:
    if hasattr(action, "layers"):
        return [
            fc
            for layer in action.layers
            for strip in layer.strips
            for bag in strip.channelbags
            for fc in bag.fcurves
        ]
    return list(action.fcurves)


KINDS = [
    ("graph", "Motion graph", "Arikan & Forsyth 2002: goals, lengths (the graph engine)"),
    ("control", "Control (walks from paths)", "Hsu et al. 2004: walk along a path; the clips are walks"),
    ("annotated", "Annotated", "Arikan et al. 2003: a label timeline"),
    ("rhythm", "Rhythm", "Kim et al. 2003: dancing to music"),
    ("clips", "Clips", "plain excerpts"),
]


def wait_database(client: SegueClient, db: Mapping[str, Any], guard: float = WAIT_GUARD_S) -> dict[str, Any]:
    """Poll a database until it is ready (``SegueError`` when it failed or the guard passed)."""
    deadline = time.monotonic() + guard
    info = dict(db)
    while info.get("status") not in ("ready", "failed"):
        if time.monotonic() > deadline:
            raise SegueError(
                0, "timeout", f"database {info.get('id')} still {info.get('status')} after {guard:.0f} s"
            )
        time.sleep(0.2)
        info = client.database(str(info["id"]))
    if info["status"] == "failed":
        raise SegueError(422, "build_failed", f"database {info.get('id')} failed: {info.get('error')}")
    return info


class SEGUE_OT_build_database(bpy.types.Operator):
    """Build a database from uploaded clips (those this session uploaded unless named)"""

    bl_idname = "segue.build_database"
    bl_label = "Build database"

    kind: EnumProperty(name="Kind", items=KINDS, default="graph")
    clips: StringProperty(
        name="Clips", description="clip names, comma separated (default: uploaded this session)"
    )
    spec: StringProperty(name="Spec", description='more of the spec as JSON, e.g. {"tau": 1.2}')
    name: StringProperty(name="Name")
    wait: BoolProperty(name="Wait", description="return once it is built (scripts)")

    def execute(self, context: bpy.types.Context) -> set[str]:
        try:
            client = _client()
            spec = json.loads(self.spec) if self.spec.strip() else {}
            if not isinstance(spec, dict):
                raise ValueError("the spec must be a JSON object")
            names = [c.strip() for c in self.clips.split(",") if c.strip()] or list(SESSION.uploaded)
            spec.setdefault("kind", self.kind)
            if self.name:
                spec.setdefault("name", self.name)
            if spec["kind"] == "control" and "pairs" not in spec:
                spec["pairs"] = [{"target": n} for n in names]
                spec.setdefault("segmentation", {"method": "footplants"})
            elif "clips" not in spec:
                if not names:
                    raise ValueError("no clips: upload an action first, or name clips")
                spec["clips"] = [
                    {"bvh": n, **({"labels": SESSION.clip_labels[n]} if n in SESSION.clip_labels else {})}
                    for n in names
                ]
            info = client.build_database(spec)
            if self.wait:
                info = wait_database(client, info)
            refresh_lists()
        except (SegueError, ValueError) as exc:
            return _fail(self, getattr(exc, "message", str(exc)))
        context.scene.segue.database = str(info["id"])
        self.report({"INFO"}, f"database {str(info['id'])[:12]} {info['status']}")
        return {"FINISHED"}


# -- generating -----------------------------------------------------------------------------------
class _Rig:
    """What a job's thread needs of one armature (read in the main thread)."""

    def __init__(self, obj: bpy.types.Object) -> None:
        self.name = obj.name
        self.upload_names = scene.upload_names(obj)
        self.bone_of = {v: k for k, v in self.upload_names.items()}
        self.rest = scene.rest_bones(obj)
        self.world = scene.matrix_tuple(obj.matrix_world)
        self.hip_height = scene.hip_height(obj)
        self.hips = scene.roles_of(obj).get("Hips", "")
        self.fingerprint = scene.rig_fingerprint(obj)
        self.glb: bytes | None = None
        self.file_id = SESSION.rig_files.get((SESSION.url, self.fingerprint))
        if self.file_id is None:
            self.glb = scene.export_rig(obj)


class _Job:
    """One Generate: the rigs, the request's parts, and the thread following it."""

    def __init__(
        self, view: JobView, rigs: list[_Rig], build: Callable[[], Mapping[str, Any]], fps: float
    ) -> None:
        self.view, self.rigs, self.fps = view, rigs, fps
        self.start_frame = 0
        self.frame = SegueFrame()
        self.frames: list[SegueFrame] = []
        self.poses: list[dict[str, list[Any]]] = []
        self.goals: list[authoring.Goal] = []
        client = _client()
        self.runner = JobRunner(client, build, download=self.download, prepare=self.prepare)
        view.runner = self.runner

    def ensure_rigs(self, client: SegueClient) -> None:
        for rig in self.rigs:
            if rig.file_id is None and rig.glb is not None:
                info = client.upload_file(rig.glb, f"{re.sub(r'[^A-Za-z0-9_.-]+', '_', rig.name)}.glb")
                rig.file_id = str(info["id"])
                SESSION.rig_files[(client.url, rig.fingerprint)] = rig.file_id

    def download(self, rid: str) -> bytes:
        client = _client()
        t = time.perf_counter()
        parts = []
        for k, rig in enumerate(self.rigs):
            params: dict[str, Any] = {"format": "glb", "result": rid, "character": rig.file_id,
                                      "animation_only": True, "fps": self.fps}  # fmt: skip
            if len(self.rigs) > 1:
                params["dancer"] = k
            parts.append(client.result(self.runner.job_id or "", **params))  # set by this thread
        self.view.timings.setdefault("download_s", time.perf_counter() - t)
        return json.dumps([p.hex() for p in parts]).encode() if len(parts) > 1 else parts[0]

    def prepare(self, raw: bytes) -> list[binding.Binding]:
        parts = [bytes.fromhex(h) for h in json.loads(raw)] if len(self.rigs) > 1 else [raw]
        placement = self.frame.placement()
        return [
            binding.plan(p, rig.bone_of, rig.rest, rig.world, placement)
            for p, rig in zip(parts, self.rigs, strict=True)
        ]


JOBS: dict[str, _Job] = {}
"""The job being followed (one at a time), by its view's action name."""


def _action_name(job_id: str, rig: str, many: bool) -> str:
    return f"Segue {job_id[:12]}" + (f" {rig}" if many else "")


def handle(job: _Job, msg: Message) -> None:
    """Apply one message of the job's thread (main thread: keys actions, fills the panel)."""
    view = job.view
    if msg.kind == "submitted":
        view.id = str(msg.data["id"])
        view.state = str(msg.data.get("status", "queued"))
        view.timings["submitted_s"] = msg.at - view.pressed_at
    elif msg.kind == "started":
        view.state = "running" if view.state != "cancelling" else view.state
    elif msg.kind == "solution":
        t0 = time.perf_counter()
        many = len(job.rigs) > 1
        job.poses = []
        for rig, prepared in zip(job.rigs, msg.prepared, strict=True):
            obj = bpy.data.objects.get(rig.name)
            if obj is None:
                continue
            step = 1.0
            _, poses = scene.key_result(
                obj, prepared, job.start_frame, step, _action_name(view.id, rig.name, many)
            )
            job.poses.append({rig.hips: scene.world_heads(obj, poses, rig.hips)} if rig.hips else {})
        view.action_name = _action_name(view.id, job.rigs[0].name, many)
        view.solutions += 1
        view.shown = str(msg.data.get("result", ""))
        view.score = msg.data.get("score")
        view.ok = msg.data.get("ok")
        view.reasons = [str(r) for r in msg.data.get("reasons") or []]
        if view.first_solution_s is None:
            view.first_solution_s = time.perf_counter() - view.pressed_at
            view.timings["solution_seen_s"] = float(msg.data.get("seen_at", msg.at)) - view.pressed_at
            view.timings["prepared_s"] = msg.at - view.pressed_at
            view.timings["keying_s"] = time.perf_counter() - t0
        if view.state in ("submitting", "queued"):
            view.state = "running"
        _redraw()
    elif msg.kind == "report":
        report = msg.data["report"]
        view.ok = bool(report.get("ok", view.ok))
        view.reasons = [str(r) for r in report.get("reasons") or []]
        view.goals = _goal_results(job, report)
        _redraw()
    elif msg.kind == "end":
        view.state = str(msg.data.get("type"))
        if view.state == "failed":
            err = msg.data.get("error") or {}
            view.message = str(err.get("message") if isinstance(err, dict) else err)
        else:
            view.message = str(msg.data.get("stopped_reason") or msg.data.get("stopped") or "")
        _redraw()
    elif msg.kind == "error":
        view.state = "failed"
        view.message = str(msg.data.get("message"))
        SESSION.error = view.message
        _redraw()


def _goal_results(job: _Job, report: Mapping[str, Any]) -> list[GoalResult]:
    out = []
    by_dancer: dict[int, list[authoring.Goal]] = {}
    for g in sorted(job.goals, key=lambda g: g.frame):
        by_dancer.setdefault(g.dancer if len(job.rigs) > 1 else 0, []).append(g)
    for entry in authoring.goal_errors(report):
        goals = by_dancer.get(entry["dancer"], [])
        if not goals or entry["index"] >= len(goals):
            continue
        g = goals[entry["index"]]
        reached = None
        heads = job.poses[entry["dancer"]] if entry["dancer"] < len(job.poses) else {}
        seq: list[Any] = next(iter(heads.values()), [])
        k = round(g.frame - job.start_frame)
        if seq and 0 <= k < len(seq):
            reached = seq[k]
        report_cm = float(entry["error_cm"]) if entry["error_cm"] is not None else None
        if reached is None:
            out.append(GoalResult(g.name, g.position, None, report_cm, entry["satisfied"], report_cm))
            continue
        rig_cm = 100.0 * math.hypot(reached[0] - g.position[0], reached[1] - g.position[1])
        frame = job.frames[entry["dancer"]] if entry["dancer"] < len(job.frames) else job.frame
        tolerance = float(entry.get("tolerance_cm") or 5.0) * frame.scale
        out.append(GoalResult(g.name, g.position, reached, rig_cm, rig_cm <= tolerance, report_cm))
    return out


def _redraw() -> None:
    wm = getattr(bpy.context, "window_manager", None)
    for window in getattr(wm, "windows", []) if wm else []:
        for area in window.screen.areas:
            if area.type in ("VIEW_3D", "PROPERTIES"):
                area.tag_redraw()


def drain(job: _Job, block: float = 0.0) -> bool:
    """Apply what the job's thread has received; True while the job is followed."""
    runner = job.runner
    while True:
        try:
            msg = runner.messages.get(timeout=block) if block > 0 else runner.messages.get_nowait()
        except queue.Empty:
            break
        handle(job, msg)
        block = 0.0
    return runner.is_alive() or not runner.messages.empty()


def _timer() -> float | None:
    job = next(iter(JOBS.values()), None)
    if job is None:
        return None
    if drain(job):
        return DRAIN_S
    JOBS.clear()
    return None


class SEGUE_OT_generate(bpy.types.Operator):
    """Generate motion on the active armature (and the other selected ones: one per dancer) with a
    Segue database; each better solution replaces the armature's action as it arrives"""

    bl_idname = "segue.generate"
    bl_label = "Generate"
    bl_options = {"REGISTER"}

    database: StringProperty(name="Database", description="id, id prefix or name (default: the panel's)")
    request: StringProperty(
        name="Request", description="the request as the HTTP API takes it (JSON); the database is added"
    )
    scene_goals: BoolProperty(
        name="Scene goals",
        description="add what the scene authors: goal empties, path, markers, music, leader",
        default=False,
    )
    wait: BoolProperty(name="Wait", description="block until the job ends (scripts, tests)", default=False)
    armatures: StringProperty(
        name="Armatures",
        description="the dancers, comma separated (default: the active armature, then the other "
        "selected ones)",
    )
    path: StringProperty(name="Path", description="a curve object: the path to walk (default: the panel's)")
    speed: FloatProperty(
        name="Speed",
        description="walking speed along the path, m/s (0: the panel's)",
        default=0.0,
        min=0.0,
        max=10.0,
    )
    bpm: FloatProperty(
        name="BPM",
        description="music tempo when the scene has no sound strip (0: the panel's)",
        default=0.0,
        min=0.0,
        max=400.0,
    )
    leader: StringProperty(
        name="Leader", description="an armature whose action leads (Partner databases; default: the panel's)"
    )
    timeout: FloatProperty(
        name="Timeout",
        description="wait=True: give up after this many seconds",
        default=WAIT_GUARD_S,
        min=1.0,
    )

    def _dancers(self, context: bpy.types.Context) -> list[bpy.types.Object]:
        if self.armatures.strip():
            out = []
            for n in self.armatures.split(","):
                obj = bpy.data.objects.get(n.strip())
                if obj is None or obj.type != "ARMATURE":
                    raise RoleError(f"no armature {n.strip()!r}")
                out.append(obj)
            return out
        active = context.active_object
        if active is None or active.type != "ARMATURE":
            raise RoleError("make your character's armature the active object")
        others = [o for o in context.selected_objects if o.type == "ARMATURE" and o != active]
        return [active, *sorted(others, key=lambda o: o.name)]

    def _start(self, context: bpy.types.Context) -> _Job:
        if any(j.view.running for j in JOBS.values()):
            raise SegueError(0, "busy", "a job is running: cancel it first")
        JOBS.clear()
        pressed = time.perf_counter()
        client = _client()
        settings = _settings(context)
        ref = self.database or settings.database
        if not ref:
            raise SegueError(0, "no_database", "pick a database")
        db = SESSION.database(ref)
        if db is None:
            refresh_lists()
            db = SESSION.database(ref)
        if db is None:
            raise SegueError(404, "not_found", f"no database {ref!r} on {client.url}")
        db_id = str(db["id"])
        base = json.loads(self.request) if self.request.strip() else {}
        if not isinstance(base, dict):
            raise SegueError(0, "bad_request", "the request must be a JSON object")
        base["database"] = db_id
        engine = authoring.ENGINE_OF_KIND.get(str(db.get("kind")))
        if engine is not None:
            base.setdefault("engine", engine)
        dancers = self._dancers(context)
        sc = context.scene
        rigs = [_Rig(o) for o in dancers]
        fps = scene.scene_fps(sc)
        inputs: authoring.SceneInputs | None = None
        anchor = (0.0, 0.0)
        leader_bvh: tuple[str, str] | None = None
        audio: tuple[str, int] | None = None
        if self.scene_goals:
            path_name = self.path or (settings.path.name if settings.path else "")
            path = bpy.data.objects.get(path_name) if path_name else None
            if path_name and path is None:
                raise SegueError(0, "bad_request", f"no curve {path_name!r}")
            speed = self.speed or settings.speed
            bpm = self.bpm or settings.bpm or None
            inputs = scene.scene_inputs(sc, dancers, path, speed, bpm)
            audio = scene.sound_strip(sc)
            leader_name = self.leader or (settings.leader.name if settings.leader else "")
            anchor = scene.anchor_of(inputs, dancers[0])
            if leader_name:
                leader = bpy.data.objects.get(leader_name)
                if (
                    leader is None
                    or leader.type != "ARMATURE"
                    or leader.animation_data is None
                    or leader.animation_data.action is None
                ):
                    raise SegueError(
                        0, "bad_request", f"the leader {leader_name!r} must be an armature with an action"
                    )
                anchor = (0.0, 0.0) if not inputs.goals else anchor
                text = scene.export_clip(leader, leader.animation_data.action, keep_names=True, origin=anchor)
                leader_bvh = (text, f"{re.sub(r'[^A-Za-z0-9_.-]+', '_', leader.name)}-leader.bvh")
        view = JobView(db_id, [r.name for r in rigs], pressed_at=pressed)
        view.timings["scene_s"] = time.perf_counter() - pressed
        SESSION.job = view

        job: _Job

        def build() -> Mapping[str, Any]:
            c = _client()
            t = time.perf_counter()
            job.ensure_rigs(c)
            summary = db.get("summary") or c.database(db_id).get("summary") or {}
            view.timings["uploads_s"] = time.perf_counter() - t
            if inputs is None:
                job.start_frame = sc.frame_start
                return base
            if leader_bvh is not None:
                inputs.leader = str(c.upload_clip(leader_bvh[0].encode(), leader_bvh[1], units="m")["name"])
            if audio is not None and str(summary.get("kind")) == "rhythm" and "music" not in base:
                with open(audio[0], "rb") as fh:
                    info = c.upload_file(fh.read(), os.path.basename(audio[0]))
                inputs.audio, inputs.audio_start = str(info["id"]), audio[1]
            ref = (summary.get("skeleton") or {}).get("hip_height_m")
            frames = [
                SegueFrame(
                    anchor, (r.hip_height / ref) if (r.hip_height and ref and leader_bvh is None) else 1.0
                )
                for r in rigs
            ]
            job.frame, job.frames = frames[0], frames
            job.goals = list(inputs.goals)
            authored = authoring.scene_request(base, summary, inputs, job.frame, frames)
            job.start_frame = authored.start_frame
            return authored.request

        job = _Job(view, rigs, build, fps)
        if not self.scene_goals:
            job.start_frame = sc.frame_start
        JOBS[view.database] = job
        job.runner.start()
        return job

    def execute(self, context: bpy.types.Context) -> set[str]:
        try:
            job = self._start(context)
        except (SegueError, RoleError, authoring.AuthoringError, gltf.GltfError, ValueError) as exc:
            return _fail(self, getattr(exc, "message", str(exc)))
        if not self.wait:
            if not bpy.app.timers.is_registered(_timer):
                bpy.app.timers.register(_timer, first_interval=DRAIN_S)
            return {"FINISHED"}
        deadline = time.monotonic() + self.timeout
        while drain(job, block=0.1):
            if time.monotonic() > deadline:
                job.runner.cancel()
                job.runner.abandon()
                return _fail(self, f"the job did not end within {self.timeout:.0f} s (cancelled)")
        JOBS.clear()
        view = job.view
        if view.state == "failed":
            return _fail(self, view.message or "the job failed")
        self.report(
            {"INFO"}, f"{view.state}: {view.solutions} solution(s), quality {'ok' if view.ok else 'not ok'}"
        )
        return {"FINISHED"}

    def invoke(self, context: bpy.types.Context, event: bpy.types.Event) -> set[str]:
        if self.wait:
            return self.execute(context)
        try:
            self._job = self._start(context)
        except (SegueError, RoleError, authoring.AuthoringError, gltf.GltfError, ValueError) as exc:
            return _fail(self, getattr(exc, "message", str(exc)))
        wm = context.window_manager
        self._timer = wm.event_timer_add(DRAIN_S, window=context.window)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context: bpy.types.Context, event: bpy.types.Event) -> set[str]:
        job: _Job = self._job
        if event.type == "ESC" and job.view.running:
            job.runner.cancel()
            job.view.state = "cancelling"
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        if drain(job):
            return {"PASS_THROUGH"}
        context.window_manager.event_timer_remove(self._timer)
        JOBS.clear()
        view = job.view
        if view.state == "failed":
            self.report({"ERROR"}, view.message or "the job failed")
            return {"CANCELLED"}
        self.report({"INFO"}, f"{view.state}: {view.solutions} solution(s)")
        return {"FINISHED"}


class SEGUE_OT_cancel(bpy.types.Operator):
    """Stop the running job; the character keeps the best motion so far"""

    bl_idname = "segue.cancel"
    bl_label = "Cancel"

    def execute(self, context: bpy.types.Context) -> set[str]:
        view = SESSION.job
        if view is None or view.runner is None or not view.running:
            return _fail(self, "no job is running")
        view.runner.cancel()
        view.state = "cancelling"
        return {"FINISHED"}


class SEGUE_OT_add_goal(bpy.types.Operator):
    """Add a body goal: an Empty at the 3D cursor, met at the current frame (or FRAME)"""

    bl_idname = "segue.add_goal"
    bl_label = "Add goal"
    bl_options = {"REGISTER", "UNDO"}

    frame: IntProperty(name="Frame", description="default (-1): the current frame", default=-1)
    heading: BoolProperty(name="Heading", description="also meet the empty's facing (its -Y)", default=False)
    dancer: IntProperty(name="Dancer", description="the dancer of several it belongs to", default=0, min=0)

    def execute(self, context: bpy.types.Context) -> set[str]:
        sc = context.scene
        frame = sc.frame_current if self.frame < 0 else self.frame
        empty = bpy.data.objects.new(f"Goal {frame}", None)
        empty.empty_display_type = "ARROWS" if self.heading else "PLAIN_AXES"
        empty.empty_display_size = 0.3
        loc = sc.cursor.location.copy()
        loc.z = 0.0
        empty.location = loc  # its facing (with heading) is its local -Y: turn it about Z
        empty["segue_frame"] = frame
        if self.heading:
            empty["segue_heading"] = True
        if self.dancer:
            empty["segue_dancer"] = self.dancer
        sc.collection.objects.link(empty)
        return {"FINISHED"}


CLASSES: Sequence[type] = (
    SEGUE_OT_connect,
    SEGUE_OT_disconnect,
    SEGUE_OT_start_local,
    SEGUE_OT_stop_local,
    SEGUE_OT_refresh,
    SEGUE_OT_detect_roles,
    SEGUE_OT_upload_action,
    SEGUE_OT_build_database,
    SEGUE_OT_generate,
    SEGUE_OT_cancel,
    SEGUE_OT_add_goal,
)
