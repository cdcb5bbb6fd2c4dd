"""The control-by-example engine as the runtime sees it (Hsu, Gentry & Popović 2004).

Database kind ``control`` (:class:`schemas.control.ControlDatabaseSpec`): synchronized
control/target pairs cut into instances (:mod:`.build`). Request ``engine: "control"``
(:class:`schemas.control.ControlRequest`): a control motion (BVH) or a performed path; the answer
is a target motion of the control's length and frame rate, in the control's world frame.

The search is anytime: a narrow-beam solve first, then a wider beam, then the exact optimum (branch
and bound against the best score so far; no optimal sequence is ever pruned), each downsampled to
``solve_fps`` then re-timed at the database rate (:mod:`.dp`), assembled on the full skeleton
(:mod:`.assemble`) and emitted as a solution when it improves the score.
"""

from __future__ import annotations

import re
import time
from collections.abc import Mapping
from dataclasses import dataclass, replace
from functools import lru_cache
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.ndimage import gaussian_filter1d
from threadpoolctl import ThreadpoolController, threadpool_limits  # type: ignore[import-untyped]

from motion import Motion, MotionError
from motion.bvh import parse_bvh
from motion.bvh_header import bvh_header
from motion.compiled import fast_fk
from motion.floorfit import faded_shifts
from motion.gltf import gltf_animations, is_gltf
from motion.goals import BodyGoal, FootplantGoal, Goal, HandholdGoal, LengthGoal, PathGoal, planted_speeds
from motion.ground import apply_floor_transform, body_root, ground_frames, static_reference_root
from motion.io import parse_motion
from motion.quality import QualityInputs
from motion.reach import reach, smooth_weights
from motion.samples import declared_units, upload_units
from motion.vectors import norms
from schemas.control import ControlDatabaseSpec, ControlRequest, unequal_pair_problems

from ..base import (
    Arrays,
    DatabaseArrays,
    DatabaseFacts,
    Emitter,
    Engine,
    EngineError,
    KindSummary,
    OutputEstimate,
    Role,
    Run,
    ShouldStop,
    Solution,
    Stopped,
)
from ..library import MotionLibrary
from .assemble import Assembled, assemble, body_rooted
from .build import ControlDatabase, build_control_database
from .dp import (
    DPResult,
    Infeasible,
    Instances,
    Interpretation,
    Timed,
    apply_constraints,
    cost_to_go,
    interpretation,
    legal_cells,
    retime,
    solve,
    typical_segment_cost,
)
from .placement import add_body_costs
from .points import derived_control, joint_cloud, resample_cloud, trajectory_control
from .schedule import BEAM_CELLS, BEAM_WIDTH, QUICK_CELLS, QUICK_WIDTH
from .session import LiveControl

Array = npt.NDArray[np.float64]

# default continuity weights (seconds), chosen experimentally as in the paper: databases of control
# motions (a leader drives a follower; leave-one-dance-out on the 14 CMU salsa couples: mean follower
# error 0.163 x height at 0.1, 0.167 at 0.2, 0.192 at 0.6) and derived walk controls (a path)
_HANDS = re.compile(r"hand|wrist", re.IGNORECASE)

HOLD_BLEND_S = 0.15
"""Fade in and out of the hand-hold correction, seconds."""
HOLD_SMOOTH_S = 0.1
"""Gaussian smoothing (sigma, seconds) of the hand-hold correction."""

K_MOTION = 0.1
K_WALK = 0.2


BODY_FADE_S = 2.0
"""A body placement's correction fades in and out over this long before and after it, seconds."""

PATH_TOLERANCE_CM = 10.0
"""How far (RMS) a walker's body may be from a performed path and still follow it: the hips sway
a few centimetres either side of the path at every step."""


SIZE_TOLERANCE = 0.10
"""How far (relative) a control motion's size may be from the database's controls'
(:meth:`ControlEngine._check_size`): people differ by less; a wrong unit by more (CMU "_scaled"
files taken as metres: 22 %)."""


def control_extent(cloud: Array) -> float:
    """The size of a control cloud ``(F, P, 3)`` (metres): the median over frames of the vertical
    extent of its points (with the default control joints, head to hips or hands)."""
    y = np.asarray(cloud)[..., 1]
    return float(np.median(y.max(axis=1) - y.min(axis=1))) if y.size else 0.0


@dataclass(slots=True)
class ControlInputCloud:
    """The control as a point cloud at its own rate: ``cloud (F, P, 3)`` metres, ``fps``; for a
    performed path, the path itself (``path (F, 2)`` metres, after the request's smoothing)."""

    cloud: Array
    fps: float
    source: str
    path: Array | None = None


@dataclass(slots=True)
class _Interpreted:
    """A control interpreted against the database at the solve rate (:meth:`ControlEngine._interpret`)."""

    rate: float  # solve rate, fps
    x_full: Array  # (F, P, 3) the control at the database rate
    inst: Instances
    cell_inst: npt.NDArray[np.intp]  # (C,) instance of each legal cell
    cell_dur: npt.NDArray[np.intp]  # (C,) its duration, solve frames
    constraints: list[tuple[int, float]]  # (instance, time s) hard constraints
    interp: Interpretation
    to_go: Array
    d_unit: float  # typical cost of interpreting one segment
    k: float  # continuity weight
    window: int  # full-rate frames per solve frame (re-timing window)


@lru_cache(maxsize=1)
def _thread_pools() -> ThreadpoolController:
    """The process's thread pools (BLAS, OpenMP), found once: ``threadpool_limits`` looks for the
    loaded libraries again at every call (reading the process's memory map, ~4 ms per request once
    numba and its LLVM are loaded)."""
    return ThreadpoolController()


def _header_frames(request: ControlRequest, ref: str, fps: float) -> int | None:
    """Output frames at ``fps`` of the control BVH ``ref``, from its header only (None when it is
    not attached or its header is unreadable)."""
    try:
        data = bytes(request.input_bytes(ref))
        if data and is_gltf(data):  # a glTF file's first animation (its accessors' count and range)
            anims = gltf_animations(data, source=ref)
            return round(anims[0].duration_s * fps) + 1 if anims else None
        head = bvh_header(data) if data else None
    except (KeyError, MotionError):
        return None
    return None if head is None else round(head.duration_s * fps) + 1


class ControlEngine(Engine[ControlRequest, ControlDatabaseSpec]):
    """Example-based control: segment DP from a control motion to a target motion."""

    name = "control"
    kind = "control"
    request_model = ControlRequest
    spec_model = ControlDatabaseSpec

    @classmethod
    def estimate(cls, request: ControlRequest, facts: DatabaseFacts) -> OutputEstimate:
        """A path's frames at the output rate, or a control clip's from its BVH header (an
        unreadable header leaves them unknown: the search names the fault). 300 bytes per
        joint-frame."""
        base = super().estimate(request, facts)
        trajectory = request.control.trajectory
        frames = None
        if trajectory is not None:
            frames = round((len(trajectory.points) - 1) / float(trajectory.fps) * base.fps) + 1
        elif request.control.bvh is not None:
            frames = _header_frames(request, request.control.bvh, base.fps)
        return replace(base, frames=frames, bytes_per_joint_frame=300)

    @classmethod
    def summarize(cls, stored_spec: Mapping[str, Any], arrays: DatabaseArrays) -> KindSummary:
        """The pairs' roles (control, target) and whether the database follows motions or paths."""
        roles: dict[str, Role] = {}
        for pair in stored_spec.get("pairs") or []:
            roles[pair["target"]] = "target"
            if pair.get("control"):
                roles[pair["control"]] = "control"
        follows = any(p.get("control") for p in stored_spec.get("pairs") or [])
        return KindSummary(roles=roles, control="motion" if follows else "path")

    def __init__(self, library: MotionLibrary, arrays: Arrays) -> None:
        super().__init__(library, arrays)
        self.db = ControlDatabase.from_arrays(arrays)
        kept = self.db.kept
        self.kept_ = kept
        self.local_of_ = np.full(self.db.instances.shape[0], -1, dtype=np.intp)
        self.local_of_[kept] = np.arange(kept.size)
        self._targets: dict[str, tuple[Motion, int]] = {}
        self._planted_slide: float | None = None
        self._control_extent: float | None = None
        self.body_column_ = self._body_column()
        self.solver_instances_ = self.instances_for(0.0)

    def _body_column(self) -> int | None:
        """The column of the target clouds that holds the target's body (the body root of the first
        target clip's skeleton), or ``None`` when it is not among the target joints."""
        names = list(self.db.meta["target_joints"])
        if not self.db.pairs:
            return None
        skeleton = self.library.clip(self.db.pairs[0][1]).skeleton
        root = skeleton.names[body_root(skeleton)]
        return names.index(root) if root in names else None

    def instances_for(self, continuity_s: float) -> Instances:
        """The kept instances for the solver; heads and tails hold the target points at the segment
        boundary and, with ``continuity_s > 0``, also ``continuity_s / 2`` and ``continuity_s`` seconds
        before it (the same instants for head and tail), so continuity covers velocity too."""
        rows = self.db.instances[self.kept_]
        start = self.db.offsets[rows[:, 0]] + rows[:, 1]
        end = start + rows[:, 2]
        lo = self.db.offsets[rows[:, 0]]
        span = int(round(continuity_s * self.db.fps))
        back = np.unique(np.array([span, span // 2, 0])) if span > 0 else np.array([0])

        def at(frames: npt.NDArray[np.intp]) -> Array:
            idx = np.maximum(frames[:, None] - back[None, :], lo[:, None])  # (N, m)
            return np.asarray(self.db.target[idx].reshape(len(frames), -1, 3))

        return Instances(
            fps=self.db.fps,
            start=start,
            length=rows[:, 2].copy(),
            control=self.db.control,
            tails=at(end),
            heads=at(start),
            pair_bounds=np.stack((lo, self.db.offsets[rows[:, 0] + 1] - 1), axis=-1),
        )

    @classmethod
    def check_live_control(cls, database_id: str) -> None:
        """Every control database follows a live control."""

    def live_control(self, **settings: Any) -> LiveControl:
        """A live session driven by a streamed control (:class:`engines.control.session.LiveControl`;
        ``settings``: its ``latency_s``, ``k``, ``stretch_s``, ``solve_fps``, ``smoothing_s``)."""
        return LiveControl(self, **settings)

    def continuity_weight(self, request: ControlRequest) -> float:
        """The request's ``k``, or the database kind's default (:data:`K_MOTION`, :data:`K_WALK`)."""
        if request.k is not None:
            return float(request.k)
        return K_WALK if self.db.derived else K_MOTION

    def target_motion(self, name: str) -> tuple[Motion, int]:
        """A target clip ready for assembly and its body joint (:func:`.assemble.body_rooted`), cached."""
        entry = self._targets.get(name)
        if entry is None:
            entry = self._targets[name] = body_rooted(self.library.clip(name))
        return entry

    @classmethod
    def example_clips(cls, library: MotionLibrary, arrays: Arrays) -> list[int]:
        """The target clips: outputs are made of them (controls are only read)."""
        targets = {t for _, t in ControlDatabase.from_arrays(arrays).pairs}
        return [i for i, name in enumerate(library.names) if name in targets]

    @classmethod
    def spec_problems(cls, spec: ControlDatabaseSpec, frames: dict[str, int], fps: float) -> list[str]:
        """Pairs of unequal lengths under ``unequal_pairs = "refuse"`` (:func:`unequal_pair_problems`)."""
        return unequal_pair_problems(spec, frames, fps)[0]

    @classmethod
    def build(
        cls, spec: ControlDatabaseSpec, library: MotionLibrary, emit: Emitter, should_stop: ShouldStop
    ) -> Arrays:
        emit.progress(0.0, f"segments and instances of {len(library.names)} clips")
        frames = {name: m.num_frames for name, m in zip(library.names, library.motions, strict=True)}
        problems, warnings = unequal_pair_problems(spec, frames, library.fps)
        if problems:
            raise EngineError("; ".join(problems))
        for line in warnings:
            emit.progress(0.0, f"warning: {line}")
        try:
            with threadpool_limits(limits=1):
                db = build_control_database(spec, library, should_stop)
        except MotionError as exc:
            raise EngineError(str(exc)) from None
        emit.progress(1.0, f"{db.instances.shape[0]} instances, {db.kept.size} kept after clustering")
        return db.to_arrays()

    # ------------------------------------------------------------------------------------ input

    def control_cloud(self, request: ControlRequest) -> ControlInputCloud:
        """The request's control as a cloud of the database's control kind (joints or floor pair)."""
        ctl = request.control
        sep = float(self.db.meta.get("hip_separation_m", 0.2))
        if ctl.trajectory is not None:
            if not self.db.derived:
                raise EngineError(
                    "a trajectory drives a walk database (pairs without control clips); "
                    "this database's controls are motions: send a control BVH"
                )
            tr = ctl.trajectory
            cloud, path = trajectory_control(
                np.asarray(tr.points, dtype=np.float64),
                tr.fps,
                sep,
                spatial_m=tr.smoothing.spatial_m,
                temporal_s=tr.smoothing.temporal_s,
                max_speed_m_s=tr.max_speed_m_s,
                speed_window_s=tr.speed_window_s,
            )
            return ControlInputCloud(cloud, float(tr.fps), "trajectory", path)
        bvh = ctl.bvh
        if bvh is None:
            raise EngineError("the control names neither a 'bvh' file nor a 'trajectory'")
        try:
            data = request.input_bytes(bvh)
        except KeyError as exc:
            raise EngineError(str(exc.args[0])) from None
        # a motion database reads only its control joints (and their ancestors) of the control
        names = None if self.db.derived else list(self.db.meta["control_joints"])
        # a bundled sample (named sample:NAME, or uploaded as its own file) in the unit the sample
        # catalogue declares, any other file as declared or guessed
        units = ctl.units if ctl.units is not None else declared_units(bvh) or upload_units(bvh, data)
        try:
            if is_gltf(data):  # a glTF file's first animation, in metres
                motion = parse_motion(data, source=bvh, name="control")
            else:
                motion = parse_bvh(data, units=units, source=bvh, name="control", joints=names)
            if names is not None and any(n not in motion.skeleton.names for n in names):
                motion = parse_bvh(data, units=units, source=bvh, name="control")  # for the message
        except MotionError as exc:
            raise EngineError(f"control {bvh!r}: {exc}") from None
        read_as = (
            f"{motion.units!r} (as declared)"
            if ctl.units is not None
            else f"{motion.units!r} (the sample catalogue's unit)"
            if units is not None
            else f"{motion.units!r} (guessed from its height)"
        )
        motion = motion.to_units("m") if motion.units != "unknown" else motion.with_units("m")
        if motion.num_frames < 2:
            raise EngineError("the control motion needs at least 2 frames")
        pos = fast_fk(motion)[0]
        if self.db.derived:
            cloud = derived_control(motion, sep, pos)
        else:
            cloud = joint_cloud(motion, list(self.db.meta["control_joints"]), f"control {bvh!r}", pos)
            self._check_size(cloud, bvh, read_as)
        return ControlInputCloud(cloud, motion.fps, bvh)

    def _check_size(self, cloud: Array, what: str, read_as: str) -> None:
        """Refuse a control motion whose size (:func:`control_extent` of its ``(F, P, 3)`` cloud,
        metres) differs from the database's controls' by more than ``SIZE_TOLERANCE``: the
        interpretation compares positions in metres, so a control read in the wrong unit (a CMU
        "_scaled" file taken as metres: 22 % small) would be matched to the wrong segments."""
        if self._control_extent is None:
            self._control_extent = control_extent(self.db.control)
        ref, got = self._control_extent, control_extent(cloud)
        if ref <= 0 or got <= 0 or abs(got / ref - 1.0) <= SIZE_TOLERANCE:
            return
        raise EngineError(
            f"control {what!r}: its control joints span {got:.2f} m, the database's controls "
            f"{ref:.2f} m ({100 * (got / ref - 1):+.0f} %; more than {100 * SIZE_TOLERANCE:.0f} % apart): "
            f"it was read in {read_as}. Declare its unit in the request's control, e.g. "
            '{"bvh": ..., "units": "cmu-scaled"} for a CMU "_scaled" file (1.28 m; the bundled '
            'salsa samples are read so), or "cm", "m", "in"'
        )

    def _constraints(self, request: ControlRequest, t_solve: int, rate: float) -> list[tuple[int, float]]:
        """``(kept instance index, time s)`` of the request's hard constraints."""
        out: list[tuple[int, float]] = []
        inst = self.db.instances
        for i, c in enumerate(request.constraints):
            if c.instance is not None:
                if c.instance >= inst.shape[0]:
                    raise EngineError(
                        f"constraints[{i}]: no instance {c.instance} (the database has {inst.shape[0]})"
                    )
                g = int(c.instance)
            elif c.clip_frame is not None:
                pair_ids = [k for k, (ctl, tgt) in enumerate(self.db.pairs) if c.clip in (ctl, tgt)]
                if not pair_ids:
                    raise EngineError(f"constraints[{i}]: no pair uses a clip named {c.clip!r}")
                hit = np.flatnonzero(
                    np.isin(inst[:, 0], pair_ids)
                    & (inst[:, 1] <= c.clip_frame)
                    & (c.clip_frame < inst[:, 1] + inst[:, 2])
                )
                if hit.size == 0:
                    raise EngineError(
                        f"constraints[{i}]: frame {c.clip_frame} of {c.clip!r} is in no instance"
                    )
                g = int(hit[0])
            else:
                raise EngineError(f"constraints[{i}]: give either 'instance' or both 'clip' and 'clip_frame'")
            local = int(self.local_of_[self.db.representative[g]])
            if c.time_s * rate >= t_solve:
                raise EngineError(f"constraints[{i}]: time {c.time_s} s is after the end of the control")
            out.append((local, float(c.time_s)))
        return out

    # ----------------------------------------------------------------------------------- search

    def search(self, request: ControlRequest, run: Run) -> Stopped:
        """The stages of :meth:`_search` (the search's work: fixed by the request, so the same
        request gives the same bytes on any machine); the run's time cap and cancel only cut the
        stages after the first short. BLAS runs single-threaded (one reduction order)."""
        # the solver's matrices are small: BLAS threads only contend (10-50x slower on a busy machine)
        with _thread_pools().limit(limits=1):
            self._search(request, run, run.emit)
        return run.outcome()

    def _search(self, request: ControlRequest, run: Run, emit: Emitter) -> None:
        """The anytime schedule: interpret the control (:meth:`_interpret`), then solve the segment
        DP with a quick beam, a wider beam and (``exact``) the optimum, re-time every better solution
        at the full rate and emit it when that improves the score too. Every stage runs (the
        work); the time cap and a cancel stop the stages after the first (the first always
        answers)."""
        t_start = time.perf_counter()
        ctl = self.control_cloud(request)
        pb = self._interpret(request, ctl)
        prep_s = time.perf_counter() - t_start
        stages = ["quick", "beam"] + (["exact"] if request.exact else [])
        best_coarse: float | None = None
        seg_unit = pb.d_unit
        best_score = np.inf
        for stage_i, stage in enumerate(stages):
            if stage_i > 0 and run.over():
                break
            t0 = time.perf_counter()
            try:
                res = self._solve_stage(
                    pb, stage, seg_unit, best_coarse, request, run.over if stage_i else None
                )
            except InterruptedError:
                break
            except Infeasible as exc:
                if stage != "exact":
                    continue  # the beam pruned every path; a wider stage may find one
                if best_coarse is not None:
                    break
                raise EngineError(str(exc)) from None
            if stage == "quick":
                seg_unit = res.score / max(1, res.cells.size)
            solve_s = time.perf_counter() - t0
            if best_coarse is not None and res.score >= best_coarse - 1e-12:
                continue
            best_coarse = res.score
            t1 = time.perf_counter()
            timed = self._retime(
                res,
                pb.x_full,
                pb.cell_inst,
                pb.cell_dur,
                pb.rate,
                request,
                pb.constraints,
                pb.window,
                pb.inst,
            )
            retime_s = time.perf_counter() - t1
            if timed.score >= best_score:
                continue
            best_score = timed.score
            timings = {"prep_s": prep_s, "solve_s": solve_s, "retime_s": retime_s}
            emit.solution(self._assembled(pb, ctl, res, timed, stage, request, timings))

    def _interpret(self, request: ControlRequest, ctl: ControlInputCloud) -> _Interpreted:
        """The control resampled to the solve rate, the legal (segment, duration) cells and their
        interpretation costs D (with the hard constraints), the cost to go, and the weights."""
        rate_full = self.db.fps
        rate = min(float(request.solve_fps), rate_full)
        x = resample_cloud(ctl.cloud, ctl.fps, rate)
        inst = (
            self.solver_instances_ if request.continuity_s <= 0 else self.instances_for(request.continuity_s)
        )
        lengths_s = inst.length / inst.fps
        cell_inst, cell_dur = legal_cells(lengths_s, rate, request.stretch_s, request.stretch_ratio)
        constraints = self._constraints(request, x.shape[0], rate)
        rigid = request.alignment == "rigid"
        interp = interpretation(
            x, inst, cell_inst, cell_dur, rate, int(round(request.context_s * rate)), rigid=rigid
        )
        apply_constraints(
            interp.D, cell_inst, cell_dur, [(s, int(np.floor(t * rate))) for s, t in constraints]
        )
        if request.bodies:
            add_body_costs(
                interp,
                inst,
                cell_inst,
                cell_dur,
                self.db.target[:, self._body_placement_column()],
                self._body_placements(request, ctl, rate, x.shape[0]),
                float(request.body_weight),
            )
        to_go = cost_to_go(interp.D, cell_dur)
        if not np.isfinite(to_go[0]):
            shortest = float(lengths_s.min())
            raise EngineError(
                f"the control ({(ctl.cloud.shape[0] - 1) / ctl.fps:.2f} s) cannot be tiled by the database's "
                f"segments (shortest {shortest:.2f} s) within the stretch bounds and constraints"
            )
        return _Interpreted(
            rate=rate,
            x_full=resample_cloud(ctl.cloud, ctl.fps, rate_full),
            inst=inst,
            cell_inst=cell_inst,
            cell_dur=cell_dur,
            constraints=constraints,
            interp=interp,
            to_go=to_go,
            d_unit=typical_segment_cost(interp.D),
            k=self.continuity_weight(request),
            window=int(np.ceil(rate_full / rate)),
        )

    def _body_placement_column(self) -> int:
        """:attr:`body_column_`, or an error naming what a request's ``bodies`` need."""
        if self.body_column_ is None:
            raise EngineError(
                "bodies: the database's target joints do not include the target's body root "
                f"({', '.join(self.db.meta['target_joints'])}); rebuild it with the hips among target_joints"
            )
        return self.body_column_

    def _body_placements(
        self, request: ControlRequest, ctl: ControlInputCloud, rate: float, frames: int
    ) -> list[tuple[int, Array]]:
        """``(solve frame, xz)`` of the request's body placements; an error names one after the
        control's end."""
        duration = (ctl.cloud.shape[0] - 1) / ctl.fps
        out = []
        for i, b in enumerate(request.bodies):
            if b.time_s > duration + 1e-6:
                raise EngineError(
                    f"bodies[{i}]: time {b.time_s} s is after the end of the control ({duration:.2f} s)"
                )
            frame = min(int(round(b.time_s * rate)), frames - 1)
            out.append((frame, np.asarray(b.position, dtype=np.float64)))
        return out

    def _place_bodies(self, motion: Motion, request: ControlRequest) -> Motion:
        """The motion moved on the floor so that its body passes through the request's placements:
        each placement's remaining distance (what the search's choice of examples left) is faded in
        over the :data:`BODY_FADE_S` before it and out over the same time after it
        (:func:`motion.floorfit.faded_shifts`); elsewhere the motion keeps its place next to the
        control. The report measures each placement (``body[i]``) and the speeds it costs."""
        if not request.bodies:
            return motion
        n = motion.num_frames
        times = np.array([b.time_s for b in request.bodies], dtype=np.float64)
        frames = np.clip(np.round(times * motion.fps).astype(np.intp), 0, n - 1)
        xz, _ = ground_frames(motion)
        targets = np.array([b.position for b in request.bodies], dtype=np.float64)
        residuals = targets - xz[frames] * motion.metres_per_unit
        shift = faded_shifts(frames, residuals, n, max(1, int(round(BODY_FADE_S * motion.fps))))
        return apply_floor_transform(motion, np.zeros(n), shift, static_reference_root([motion]))

    def _solve_stage(
        self,
        pb: _Interpreted,
        stage: str,
        seg_unit: float,
        best_coarse: float | None,
        request: ControlRequest,
        should_stop: ShouldStop | None,
    ) -> DPResult:
        """One stage's DP: ``quick`` (a narrow beam in typical segment costs), ``beam`` (wider, in
        the quick solution's cost per segment) or ``exact`` (bounded by the best score so far)."""
        if stage == "quick":
            width: float | None = QUICK_WIDTH * pb.d_unit
        elif stage == "beam":
            width = (BEAM_WIDTH if request.beam is None else float(request.beam)) * seg_unit
        else:
            width = None
        return solve(
            pb.interp,
            pb.inst,
            pb.cell_inst,
            pb.cell_dur,
            pb.k,
            beam=width,
            max_cells=QUICK_CELLS if stage == "quick" else BEAM_CELLS if stage == "beam" else None,
            upper_bound=best_coarse if stage == "exact" else None,
            to_go=pb.to_go,
            should_stop=should_stop,
        )

    def _assembled(
        self,
        pb: _Interpreted,
        ctl: ControlInputCloud,
        res: DPResult,
        timed: Timed,
        stage: str,
        request: ControlRequest,
        timings: dict[str, float],
    ) -> Solution:
        """The target segments of a re-timed solution concatenated, smoothed and cleaned up, with
        its report."""
        t2 = time.perf_counter()
        out = assemble(
            self.db,
            self.target_motion,
            self.db.instances[self.kept_],
            timed,
            ctl.cloud.shape[0],
            ctl.fps,
            request.smoothing_s,
        )
        out.motion = self._place_bodies(out.motion, request)
        motion = self._cleanup(out, request)
        if request.hold_hands:
            motion = self._hold_hands(out, motion, ctl, timed)
        timings["post_s"] = time.perf_counter() - t2
        return self._solution(out, motion, timed, res, stage, ctl, timings, pb.cell_inst.size, request.bodies)

    def _retime(
        self,
        res: DPResult,
        x_full: Array,
        cell_inst: npt.NDArray[np.intp],
        cell_dur: npt.NDArray[np.intp],
        rate: float,
        request: ControlRequest,
        constraints: list[tuple[int, float]],
        window: int,
        inst: Instances,
    ) -> Timed:
        rate_full = self.db.fps
        seq = cell_inst[res.cells]
        coarse = np.concatenate(([0], res.ends)) * (rate_full / rate)
        coarse[-1] = x_full.shape[0]
        seg_constraints: list[tuple[int, float]] = []
        starts = np.concatenate(([0], res.ends[:-1]))
        for _, t in constraints:
            f = int(np.floor(t * rate))
            i = int(np.flatnonzero((starts <= f) & (f < res.ends))[0])
            seg_constraints.append((i, int(np.floor(t * rate_full))))
        try:
            return retime(
                x_full,
                inst,
                seq,
                coarse,
                self.continuity_weight(request),
                rate_full,
                request.stretch_s,
                request.stretch_ratio,
                window,
                seg_constraints,
                int(round(request.context_s * rate_full)),
                rigid=request.alignment == "rigid",
            )
        except Infeasible as exc:
            raise EngineError(str(exc)) from None

    def _cleanup(self, out: Assembled, request: ControlRequest) -> Motion:
        """The assembled motion with its feet kept planted where the examples' contacts say
        (:func:`motion.footskate.remove_foot_skate`, above the examples' floor)."""
        motion = out.motion
        mode = request.feet_mode()
        if mode == "free" or not self.db.contact_joints:
            return motion
        try:
            from motion.footskate import remove_foot_skate
        except ImportError:  # the cleanup is optional
            return motion
        joints = np.array([motion.skeleton.names.index(n) for n in self.db.contact_joints], dtype=np.intp)
        flags = self.db.contacts[out.global_frames]
        floor = self.foot_floor(motion.skeleton)
        lowest = None
        if floor and all(int(j) in floor for j in joints):
            lowest = np.array([floor[int(j)][1] for j in joints]) / motion.metres_per_unit
        try:
            return remove_foot_skate(
                motion, (joints, flags), floor=lowest, fk=fast_fk(motion), horizontal=mode == "lock"
            )
        except MotionError:
            return motion

    def _hold_hands(self, out: Assembled, motion: Motion, ctl: ControlInputCloud, timed: Timed) -> Motion:
        """Where the chosen examples hold hands (the database's hand-hold annotation, carried to the
        output frames), put the output's hand on the control's hand as it was in the example: the
        example's offset from the leader's hand to the follower's nearest hand, turned by the
        segment's alignment, added to the control's hand (two-bone arm IK, :func:`motion.reach.reach`,
        faded in and out over 0.15 s). Dance databases only; the motion unchanged otherwise."""
        db = self.db
        hold = db.handhold[out.global_frames] == 1
        if ctl.path is not None or db.derived or not hold.any() or ctl.cloud.shape[0] != motion.num_frames:
            return motion
        cj = [i for i, n in enumerate(db.meta["control_joints"]) if _HANDS.search(n)]
        tcols = [i for i, n in enumerate(db.meta["target_joints"]) if _HANDS.search(n)]
        if not cj or not tcols:
            return motion
        names = [db.meta["target_joints"][i] for i in tcols]
        if any(n not in motion.skeleton.names for n in names):
            return motion
        g = out.global_frames
        src_f = db.target[g][:, tcols]  # (F, Ht, 3) the example's follower hands
        src_l = db.control[g][:, cj]  # (F, Hc, 3) the example's leader hands
        apart = norms(src_f[:, :, None] - src_l[:, None])  # (F, Ht, Hc) follower hand to leader hand
        nearest = apart.argmin(axis=2)  # (F, Ht)
        rows = np.arange(g.size)[:, None]
        offset = src_f - src_l[rows, nearest]  # (F, Ht, 3) example frame
        seg = out.segment_of_frame
        c, s = timed.cos[seg][:, None], timed.sin[seg][:, None]
        turned = np.stack(
            (
                c * offset[..., 0] + s * offset[..., 2],
                offset[..., 1],
                -s * offset[..., 0] + c * offset[..., 2],
            ),
            axis=-1,
        )
        targets = (ctl.cloud[:, cj][rows, nearest] + turned) / motion.metres_per_unit
        dist = apart.min(axis=2)  # (F, Ht)
        holding = hold[:, None] & (dist < float(db.meta.get("handhold_m", 0.2)))
        blend = int(round(HOLD_BLEND_S * motion.fps))
        weights = np.stack([smooth_weights(holding[:, k], blend) for k in range(len(tcols))], axis=-1)
        joints = np.array([motion.skeleton.names.index(n) for n in names], dtype=np.intp)
        # the correction, not the target, is smoothed in time: the control's hands carry capture
        # noise and the example offsets change at segment boundaries
        fk = fast_fk(motion)
        hands = fk[0][:, joints]
        corr = gaussian_filter1d(weights[..., None] * (targets - hands), HOLD_SMOOTH_S * motion.fps, axis=0)
        moving = (np.abs(corr).max(axis=-1) > 0).astype(np.float64)
        try:
            return reach(motion, joints, hands + corr, moving, fk)
        except MotionError:
            return motion

    def examples_planted_slide(self) -> float | None:
        """The examples' own mean horizontal foot speed (m/s) where their contacts plant the feet
        (the database's target clouds and contacts, each pair apart, over 1/30 s intervals); ``None``
        when the contact joints are not among the target joints."""
        if self._planted_slide is None:
            db = self.db
            names = list(db.meta["target_joints"])
            if not db.contact_joints or any(n not in names for n in db.contact_joints):
                self._planted_slide = float("nan")
            else:
                cols = np.array([names.index(n) for n in db.contact_joints], dtype=np.intp)
                speeds = [
                    planted_speeds(db.target[a:b], cols, db.contacts[a:b], db.fps, 1.0 / 30.0)
                    for a, b in zip(db.offsets[:-1], db.offsets[1:], strict=True)
                ]
                every = np.concatenate(speeds)
                self._planted_slide = float(every.mean()) if every.size else float("nan")
        return None if np.isnan(self._planted_slide) else self._planted_slide

    def _footplant_goal(self, contacts: npt.NDArray[np.bool_], motion: Motion) -> Goal | None:
        """The propagated foot contacts as a goal of the quality report
        (:class:`motion.goals.FootplantGoal`): the output's feet slide no more where the examples
        plant them than the examples' own feet do (``None`` without contacts)."""
        tolerance = self.examples_planted_slide()
        names = motion.skeleton.names
        if tolerance is None or not contacts.any() or any(n not in names for n in self.db.contact_joints):
            return None
        joints = np.array([names.index(n) for n in self.db.contact_joints], dtype=np.intp)
        return FootplantGoal("footplants", joints, contacts, tolerance_m_s=tolerance)

    def _handhold_goal(
        self, hold: npt.NDArray[np.int8], ctl: ControlInputCloud, motion: Motion
    ) -> Goal | None:
        """The propagated hand hold as a goal of the quality report (:class:`motion.goals.HandholdGoal`):
        where the chosen examples hold hands, the output's hands should be at the control's hands
        (a motion control whose cloud has hands; ``None`` otherwise)."""
        if ctl.path is not None or self.db.derived or not (hold == 1).any():
            return None
        cj = [i for i, n in enumerate(self.db.meta["control_joints"]) if _HANDS.search(n)]
        own = [motion.skeleton.names.index(n) for n in self.db.meta["target_joints"] if _HANDS.search(n)]
        if not cj or not own or ctl.cloud.shape[0] != motion.num_frames:
            return None
        frames = np.flatnonzero(hold == 1).astype(np.intp)
        return HandholdGoal(
            "handhold",
            frames,
            np.asarray(own, dtype=np.intp),
            ctl.cloud[frames][:, cj],
            tolerance_cm=100 * float(self.db.meta.get("handhold_m", 0.2)),
            margin=int(round(HOLD_BLEND_S * motion.fps)),  # joining and letting go (see _hold_hands)
        )

    def _solution(
        self,
        out: Assembled,
        motion: Motion,
        timed: Timed,
        res: DPResult,
        stage: str,
        ctl: ControlInputCloud,
        timings: dict[str, float],
        n_cells: int,
        bodies: Any = (),
    ) -> Solution:
        db = self.db
        kept = self.kept_
        rate = db.fps
        segments = []
        first_out = np.concatenate(([0], np.array(out.cuts, dtype=np.intp)))
        for i, local in enumerate(timed.instances):
            g = int(kept[local])
            pair, start, length = (int(v) for v in db.instances[g])
            d = int(timed.bounds[i + 1] - timed.bounds[i])
            segments.append(
                {
                    "instance": g,
                    "control_clip": db.pairs[pair][0],
                    "target_clip": db.pairs[pair][1],
                    "source_start": start,
                    "source_frames": length,
                    "start_s": float(timed.bounds[i] / rate),
                    "duration_s": float(d / rate),
                    "stretch": float(d / length),
                    "heading_deg": float(np.degrees(np.arctan2(timed.sin[i], timed.cos[i]))),
                    "translation": [float(timed.tx[i]), float(timed.tz[i])],
                    **(
                        {}
                        if timed.rot is None or timed.trans is None
                        else {
                            "rotation_matrix": timed.rot[i].tolist(),
                            "translation_3d": timed.trans[i].tolist(),
                        }
                    ),
                    "interpretation": float(timed.D[i]),
                    "continuity": float(timed.C[i - 1]) if i > 0 else 0.0,
                    "first_output_frame": int(first_out[i]) if i < first_out.size else None,
                }
            )
        source = np.round(out.source_frames).astype(np.int64).tolist()  # half to even, as round()
        provenance = list(zip(out.clips, source, strict=True))
        contacts = db.contacts[out.global_frames]
        annotations: dict[str, Any] = {
            "stage": stage,
            "segments": segments,
            "foot_contacts": {
                "joints": list(db.contact_joints),
                "flags": contacts.T.astype(int).tolist(),
            },
        }
        hold = db.handhold[out.global_frames]
        if (hold >= 0).all():
            annotations["handhold"] = hold.astype(int).tolist()
        metrics = {
            "segments": float(len(segments)),
            "cells": float(n_cells),
            "expanded": float(res.expanded),
            "coarse_score": float(res.score),
            **timings,
        }
        goals: list[Goal] = [LengthGoal(ctl.cloud.shape[0])]
        hold_goal = self._handhold_goal(hold, ctl, motion)
        if hold_goal is not None:
            goals.append(hold_goal)
        for i, b in enumerate(bodies):
            frame = min(int(round(b.time_s * motion.fps)), motion.num_frames - 1)
            goals.append(BodyGoal(f"body[{i}]", frame, np.asarray(b.position, dtype=np.float64)))
        plant_goal = self._footplant_goal(contacts, motion)
        if plant_goal is not None:
            goals.append(plant_goal)
        if ctl.path is not None:
            frames = np.arange(ctl.path.shape[0], dtype=np.intp)
            goals.append(PathGoal("path", frames, ctl.path, tolerance_cm=PATH_TOLERANCE_CM))
        solution = Solution(
            motion=motion,
            score=timed.score,
            terms={"interpretation": timed.interpretation, "continuity": timed.continuity},
            provenance=provenance,
            metrics=metrics,
            annotations=annotations,
        )
        joins = np.asarray([c for c in out.cuts if 0 < c < motion.num_frames], dtype=np.intp)
        return self.finish(solution, QualityInputs(goals=tuple(goals), joins=joins), fast_fk(motion)[0])
