"""The Segue panels in the 3D view's sidebar (N panel, "Segue" tab)."""

from __future__ import annotations

import bpy

from .roles import LIMBS, missing_roles
from .state import SESSION


class _Panel:
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Segue"


class SEGUE_PT_connection(_Panel, bpy.types.Panel):
    """Connect: the service's URL and token, or a local service; status and errors."""

    bl_label = "Segue"
    bl_idname = "SEGUE_PT_connection"

    def draw(self, context: bpy.types.Context) -> None:
        layout = self.layout
        settings = context.scene.segue
        col = layout.column(align=True)
        col.prop(settings, "url")
        col.prop(context.window_manager, "segue_token")
        row = layout.row(align=True)
        if SESSION.client is None:
            row.operator("segue.connect", icon="LINKED")
        else:
            row.operator("segue.refresh", icon="FILE_REFRESH")
            row.operator("segue.disconnect", icon="UNLINKED")
        row = layout.row(align=True)
        if SESSION.local is not None and SESSION.local.running:
            row.operator("segue.stop_local", icon="CANCEL")
        else:
            row.operator("segue.start_local", icon="PLAY")
        layout.label(text=SESSION.status, icon="CHECKMARK" if SESSION.client else "INFO")
        if SESSION.client is not None:
            backend = SESSION.health.get("backend", {})
            layout.label(
                text=f"{backend.get('backend', '?')} backend, "
                f"{backend.get('workers_ready', '?')} workers ready"
            )
        if SESSION.error:
            for line in _wrap(SESSION.error):
                layout.label(text=line, icon="ERROR")


class SEGUE_PT_rig(_Panel, bpy.types.Panel):
    """Rig: which bone plays each part of the body (detected, editable)."""

    bl_label = "Rig"
    bl_parent_id = "SEGUE_PT_connection"

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        return context.active_object is not None and context.active_object.type == "ARMATURE"

    def draw(self, context: bpy.types.Context) -> None:
        layout = self.layout
        obj = context.active_object
        roles = obj.segue_roles
        layout.operator("segue.detect_roles", icon="ARMATURE_DATA")
        found = {r: getattr(roles, r) for r in ("Hips", "Head")}
        col = layout.column(align=True)
        for role in ("Hips", "Head"):
            col.prop_search(roles, role, obj.data, "bones", text=role)
        for side in ("Left", "Right"):
            box = layout.box()
            box.label(text=f"{side} side")
            c = box.column(align=True)
            for limb in LIMBS:
                c.prop_search(roles, f"{side}{limb}", obj.data, "bones", text=limb)
                found[f"{side}{limb}"] = getattr(roles, f"{side}{limb}")
        missing = missing_roles({k: v for k, v in found.items() if v})
        if missing:
            layout.label(text=f"missing: {', '.join(missing)}", icon="ERROR")
        else:
            layout.label(text="ready: roles set", icon="CHECKMARK")


class SEGUE_PT_library(_Panel, bpy.types.Panel):
    """Library: upload actions as clips, build databases, the server's databases."""

    bl_label = "Library"
    bl_parent_id = "SEGUE_PT_connection"

    def draw(self, context: bpy.types.Context) -> None:
        layout = self.layout
        row = layout.row(align=True)
        row.operator("segue.upload_action", icon="EXPORT").all_actions = False
        row.operator("segue.upload_action", text="All actions").all_actions = True
        if SESSION.uploaded:
            layout.label(text=f"uploaded: {', '.join(SESSION.uploaded[-3:])}")
        layout.operator_menu_enum("segue.build_database", "kind", text="Build database from uploads")
        layout.label(text=f"{len(SESSION.clips)} clips, {len(SESSION.databases)} databases")
        box = layout.box()
        for db in SESSION.databases[:12]:
            summary = db.get("summary") or {}
            name = db.get("name") or ", ".join((db.get("clips") or [])[:2])
            box.label(text=f"{str(db['id'])[:8]} {db.get('kind')} · {name} · {db.get('status')}"
                      + (f" · {summary.get('fps', '')} fps" if summary else ""))  # fmt: skip


class SEGUE_PT_generate(_Panel, bpy.types.Panel):
    """Generate: the database, what the scene authors for it, the job and its progress."""

    bl_label = "Generate"
    bl_parent_id = "SEGUE_PT_connection"

    def draw(self, context: bpy.types.Context) -> None:
        layout = self.layout
        settings = context.scene.segue
        layout.prop(settings, "database")
        db = SESSION.database(settings.database) if settings.database else None
        kind = str((db or {}).get("kind", ""))
        summary = (db or {}).get("summary") or {}
        if db is not None:
            layout.label(text=f"{kind} database, {db.get('status')}")
        goals = [o for o in context.scene.objects if o.type == "EMPTY" and "segue_frame" in o]
        box = layout.box()
        box.label(text="Authored in the scene", icon="SCENE_DATA")
        row = box.row()
        row.label(text=f"{len(goals)} goal empties")
        row.operator("segue.add_goal", text="Add goal", icon="EMPTY_AXIS")
        if kind == "control" and summary.get("control") == "path":
            box.prop(settings, "path")
            box.prop(settings, "speed")
        elif kind == "control":
            box.prop(settings, "leader")
        elif kind == "annotated":
            box.label(
                text=f"{len(context.scene.timeline_markers)} markers; "
                f"labels: {', '.join(summary.get('labels', [])[:6])}"
            )
        elif kind == "rhythm":
            box.prop(settings, "bpm")
            box.prop(settings, "path")
        layout.prop(settings, "request")
        dancers = [o for o in context.selected_objects if o.type == "ARMATURE"]
        if len(dancers) > 1:
            layout.label(text=f"{len(dancers)} dancers (one armature each)")
        row = layout.row(align=True)
        op = row.operator("segue.generate", icon="PLAY")
        op.scene_goals = True
        op.request = settings.request
        view = SESSION.job
        if view is not None and view.running:
            row.operator("segue.cancel", icon="CANCEL")
        if view is None:
            return
        col = layout.column(align=True)
        col.label(text=f"job {view.id[:12] or '…'}: {view.state}")
        if view.solutions:
            first = (
                f", first after {view.first_solution_s:.2f} s" if view.first_solution_s is not None else ""
            )
            col.label(text=f"{view.solutions} solution(s){first}; showing {view.shown}")
            if view.score is not None:
                col.label(text=f"score {float(view.score):.4g}")
            col.label(text=f"action: {view.action_name}")
        if view.message:
            for line in _wrap(view.message):
                col.label(text=line, icon="INFO")


class SEGUE_PT_quality(_Panel, bpy.types.Panel):
    """Quality: the report of the motion shown (ok, reasons, each goal's error)."""

    bl_label = "Quality"
    bl_parent_id = "SEGUE_PT_connection"

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        return SESSION.job is not None and SESSION.job.solutions > 0

    def draw(self, context: bpy.types.Context) -> None:
        layout = self.layout
        view = SESSION.job
        if view is None:
            return
        layout.label(text="ok" if view.ok else "not ok", icon="CHECKMARK" if view.ok else "ERROR")
        for reason in view.reasons[:8]:
            for line in _wrap(reason):
                layout.label(text=line)
        if view.goals:
            box = layout.box()
            for g in view.goals:
                err = f"{g.error_cm:.1f} cm" if g.error_cm is not None else "?"
                own = f" (report: {g.report_cm:.1f} cm)" if g.report_cm is not None else ""
                box.label(text=f"{g.name}: {err}{own}", icon="CHECKMARK" if g.satisfied else "CANCEL")


def _wrap(text: str, width: int = 48) -> list[str]:
    words, lines, line = text.split(), [], ""
    for w in words:
        if len(line) + len(w) + 1 > width and line:
            lines.append(line)
            line = w
        else:
            line = f"{line} {w}".strip()
    return [*lines, line] if line else lines


CLASSES = (SEGUE_PT_connection, SEGUE_PT_rig, SEGUE_PT_library, SEGUE_PT_generate, SEGUE_PT_quality)
