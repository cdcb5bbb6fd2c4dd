// Segue's browser front end: library (clips, databases), the viewer, and five authoring tools, all
// on the public API. window.__segue mirrors the page's state for tests (assert on state, not pixels).
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { api, ApiError, followJob, getToken, setToken } from './api.js';
import { bvhText, METRES_PER_UNIT, parseBvh, parseBvhText, skeletonJoints } from './bvh.js';
import { placeJoint, Viewer } from './viewer.js';
import { FloorPad, headingDeg } from './pad.js';
import { setupMusic } from './music.js';
import { setupGraph } from './graph.js';
import { startLiveWalk } from './livewalk.js';
import { setupCharacters } from './characters.js';

const $ = (id) => document.getElementById(id);
const VIEW_FPS = 30; // results are drawn at most at this rate (the server resamples; downloads are full rate)

export const state = {
  ready: false,
  health: null,
  samples: {},
  clips: [],
  databases: [],
  loaded: [], // names of motions parsed in the page (uploaded clips)
  viewer: { playing: false, time: 0, duration: 0, characters: [], frames: {} },
  tool: 'path',
  job: null, // {id, tool, status, submitted_ms}
  solutions: [], // {job, result, score, elapsed_ms, terms, at_ms, ok, reasons, alternative}
  quality: null, // the drawn result's {result, ok, reasons}
  current: null, // {tool, job, result, score, frames, fps, drawn_ms}
  timings: {}, // tool -> ms from pressing the button to the first solution drawn
  firstDraw: {}, // tool -> where that time went (event arrival, download, parse, draw; ms)
  builds: [], // {database, kind, status, fraction, message}
  errors: [], // {where, code, message}
  downloads: [], // {format, bytes, animations, duration_s}
  beats: 0,
  path: { points: [], fps: 30 },
  constraints: [],
  timeline: { tracks: [] },
  music: { running: false, beats: 0, directions: [], mode: null },
};
window.__segue = state;
// test hook: drop the current job's event socket as a network failure would (the page resumes)
state.dropEvents = () => {
  const socket = active && active.handle.socket;
  if (socket) socket.close(4000, 'dropped by the test hook');
  return Boolean(socket);
};

const viewer = new Viewer($('viewer'));
// test hook: the viewer's pixels lit by the characters, drawn as bodies and as stick figures at
// the same moment: pixels brighter (luminance, 0-255) by more than `by` than the same view without
// characters (the floor, its marks and trails, which both share, cancel out)
state.litPixels = (by = 20) => {
  viewer.pause();
  const lum = (px, i) => 0.2126 * px[i] + 0.7152 * px[i + 1] + 0.0722 * px[i + 2];
  const floor = viewer.capture('hidden');
  const count = (px) => {
    let n = 0;
    for (let i = 0; i < px.length; i += 4) if (lum(px, i) - lum(floor, i) > by) n += 1;
    return n;
  };
  return { bodies: count(viewer.capture({ bodies: true, bones: false })), sticks: count(viewer.capture({ bodies: false, bones: true })), pixels: floor.length / 4 };
};
let music = null; // the Music tool (set up below)
let timeline = null; // the Timeline tool (set up below)
const clipMotions = new Map(); // clip name -> parsed motion (metres)
// What a database holds (labels, clips, skeleton, what drives it) comes from the API
// (GET /v1/databases: each ready database's `summary`), so every tool works on any database,
// whoever built it (this page, the CLI's spec over HTTP, another client).
const summaryOf = (id) => (state.databases.find((d) => d.id === id) || {}).summary || null;

// ---------------------------------------------------------------- errors
const errorCodes = {}; // where -> the code of the error shown there
export function showError(where, exc) {
  const el = $(`err-${where}`);
  const message = exc instanceof ApiError ? `${exc.message} [${exc.code}]` : String(exc.message || exc);
  if (el) el.textContent = message;
  errorCodes[where] = exc.code || 'error';
  state.errors.push({ where, code: exc.code || 'error', message: exc.message || String(exc), status: exc.status || 0 });
  if (!(exc instanceof ApiError)) console.error(exc);
}

export function clearError(where) {
  const el = $(`err-${where}`);
  if (el) el.textContent = '';
  delete errorCodes[where];
}

// A tool's "no database" / "database not ready" error is stale once its picker holds a ready
// database (built since, or picked): it goes, instead of staying beside a tool that now works.
const TOOL_SELECTS = { path: 'path-db', partner: 'partner-db', constraints: 'cons-db', timeline: 'tl-db', music: 'music-db' };
const DATABASE_ERRORS = new Set(['no_database', 'database_not_ready', 'database_building']);
function clearStaleDatabaseErrors() {
  for (const [where, select] of Object.entries(TOOL_SELECTS)) {
    if (DATABASE_ERRORS.has(errorCodes[where]) && $(select).value) clearError(where);
  }
}
for (const select of Object.values(TOOL_SELECTS)) $(select).addEventListener('change', clearStaleDatabaseErrors);

async function guarded(where, fn) {
  clearError(where);
  try {
    return await fn();
  } catch (exc) {
    showError(where, exc);
    return undefined;
  }
}

// the character picker and the bodies it draws (web/js/characters.js)
const characters = setupCharacters({ state, $, api, viewer, guarded, clearError, showError, clipName });

// ---------------------------------------------------------------- viewer transport
let scrubbing = false;
function fmt(t) {
  return t.toFixed(2);
}
viewer.onChange((v) => {
  const d = v.duration;
  state.viewer = { playing: v.playing, time: v.time, duration: d, characters: [...new Set([...v.characters.keys(), ...v.bodies.keys()])], frames: { ...(v.frames || {}) },
    roots: Object.fromEntries([...v.characters].map(([k, c]) => [k, c.motion.joints ? c.motion.joints[c.root] : c.root])),
    bodies: [...v.bodies.keys()], showBodies: v.showBodies, showBones: v.showBones, floorY: v.floorY, speed: v.speed, follow: v.followMode, fps: v.fps,
    contacts: Object.fromEntries([...v.contacts].map(([k, marks]) => [k, marks.length])), goals: v.goals ? v.goals.children.length : 0 };
  $('play').textContent = v.playing ? 'Pause' : 'Play';
  $('frame').textContent = `f ${Math.round(v.time * v.fps)}`;
  if (!scrubbing) $('scrub').value = d > 0 ? String(v.time / d) : '0';
  $('time').textContent = `${fmt(v.time)} / ${fmt(d)} s`;
  if (music) music.onTime(v.time, v.playing);
  if (timeline) timeline.showTime(v.time);
});
$('play').onclick = () => (viewer.playing ? viewer.pause() : viewer.play());
$('scrub').addEventListener('pointerdown', () => { scrubbing = true; viewer.pause(); });
$('scrub').addEventListener('pointerup', () => { scrubbing = false; });
$('scrub').addEventListener('input', () => viewer.seek(Number($('scrub').value) * viewer.duration));
$('speed').onchange = () => { viewer.speed = Number($('speed').value); viewer.emit(); };
$('step-back').onclick = () => viewer.step(-1);
$('step-fwd').onclick = () => viewer.step(1);
document.addEventListener('keydown', (ev) => {
  // space plays / pauses, "," and "." step a frame, unless typing in a field
  if (['INPUT', 'TEXTAREA', 'SELECT', 'BUTTON'].includes(document.activeElement.tagName)) return;
  if (ev.code === 'Space') {
    ev.preventDefault();
    if (viewer.playing) viewer.pause(); else viewer.play();
  } else if (ev.key === ',' || ev.key === '.') {
    viewer.step(ev.key === '.' ? 1 : -1);
  }
});
$('trail').onchange = () => viewer.setTrails($('trail').checked);
$('show-body').onchange = () => viewer.setDisplay({ bodies: $('show-body').checked });
$('show-bones').onchange = () => viewer.setDisplay({ bones: $('show-bones').checked });
$('follow').onchange = () => viewer.setFollow($('follow').value);

// ---------------------------------------------------------------- library
function sampleLabel(file) {
  return state.samples[file] || file;
}

// the bundled CMU clips, offered for upload (specs may also name them sample:NAME)
async function loadSamples() {
  state.samples = await api.samples();
  const sel = $('sample-select');
  sel.textContent = '';
  for (const file of Object.keys(state.samples)) sel.add(new Option(sampleLabel(file), file));
}
$('sample-upload').onclick = () =>
  guarded('upload', async () => {
    const file = $('sample-select').value;
    if (file) await uploadClip(file, await api.sampleBytes(file));
  });

// a clip the browser cannot read as uploaded (glTF, or a BVH that needed the service's warnings)
const readByService = (info) => info.format === 'gltf' || (info.warnings || []).length > 0;

async function uploadClip(name, bytes) {
  const info = await api.uploadClip(name, bytes);
  // what the file needed to be read (it was read): shown under the upload button
  $('warn-upload').textContent = (info.warnings || []).map((w) => `${info.name}: ${w}`).join('\n');
  const motion = readByService(info)
    ? parseBvhText(await bvhText(await api.clipBytes(info.id, true)), info.name, METRES_PER_UNIT[info.units] || 1)
    : await parseBvh(bytes, info.name, info.units);
  clipMotions.set(clipName(info), motion);
  await refreshClips();
  viewClip(clipName(info));
  if (!state.loaded.includes(clipName(info))) state.loaded.push(clipName(info));
  return info;
}

// how databases name a clip by default: the file name without .bvh/.gz/.glb/.gltf
function clipName(info) {
  return info.name.replace(/\.gz$/, '').replace(/\.(bvh|glb|gltf)$/, '');
}

function viewClip(name) {
  const motion = clipMotions.get(name);
  if (!motion) return false;
  clearResults();
  viewer.set('clip', motion);
  characters.show('clip', { kind: 'motion', motion, hips: motion.joints[placeJoint(motion)] });
  state.current = { tool: 'library', clip: name, frames: motion.frames, fps: motion.fps };
  state.shownTool = 'library';
  $('sol-info').textContent = `clip ${name} · ${motion.frames} frames at ${motion.fps.toFixed(0)} fps`;
  $('sol-quality').hidden = true;
  for (const id of ['dl-bvh', 'dl-glb']) $(id).disabled = true;
  viewer.seek(0);
  viewer.play();
  return true;
}

$('clip-file').onchange = async (ev) => {
  $('warn-upload').textContent = '';
  for (const file of ev.target.files) {
    await guarded('upload', async () => uploadClip(file.name, await file.arrayBuffer()));
  }
  ev.target.value = '';
};

async function refreshClips() {
  state.clips = await api.clips();
  const list = $('clip-list');
  list.textContent = '';
  for (const c of state.clips) {
    const li = document.createElement('li');
    li.dataset.clip = clipName(c);
    li.innerHTML = `<span class="grow" title="${c.id}"></span><span class="muted mono"></span>`;
    li.firstChild.textContent = c.name;
    li.children[1].textContent = `${c.frames}f ${c.fps.toFixed(0)}fps ${c.height_m.toFixed(2)}m`;
    if (clipMotions.has(clipName(c))) {
      const b = document.createElement('button');
      b.textContent = 'view';
      b.onclick = () => viewClip(clipName(c));
      li.appendChild(b);
    }
    list.appendChild(li);
  }
  // the character picker beside the downloads: glTF/GLB files and any uploaded clip's skeleton
  await characters.refresh();
  const checks = $('db-clips');
  const checked = new Set([...checks.querySelectorAll('input:checked')].map((i) => i.value));
  checks.textContent = '';
  for (const c of state.clips) {
    const label = document.createElement('label');
    label.innerHTML = '<input type="checkbox"> <span></span>';
    label.firstChild.value = clipName(c);
    label.firstChild.checked = checked.has(clipName(c));
    label.lastChild.textContent = clipName(c);
    checks.appendChild(label);
  }
  for (const sel of document.querySelectorAll('.clip-select')) {
    const keep = sel.value;
    sel.textContent = '';
    for (const c of state.clips) sel.add(new Option(clipName(c), clipName(c)));
    if (keep) sel.value = keep;
  }
  tools.partner?.refreshLeaders();
  if (state.ready) showWelcome();
}

// how a database is named in lists and pickers: its name, else its clips; its kind, and what drives
// a control database (a leader's motion: Partner; a floor path: Path)
export function dbLabel(d) {
  const clips = d.clips || [];
  const name = d.name || (clips.length ? `${clips[0]}${clips.length > 1 ? ` +${clips.length - 1}` : ''}` : d.id.slice(0, 8));
  const drive = d.summary && d.summary.control ? ` (${d.summary.control === 'path' ? 'walks from a path' : 'partner'})` : '';
  const edited = d.derived_from ? ' (edited graph)' : '';
  return `${name} · ${d.kind}${drive}${edited}`;
}

// what a graph build kept (GET /v1/databases/{id}: summary.graph): the clips a search can play and
// those left out of the motion graph, with why; null for other kinds
export function keptNote(d) {
  const g = d.summary && d.summary.graph;
  if (!g) return null;
  const total = g.kept_clips + g.dropped.length;
  const lines = [`kept ${g.kept_clips} of ${total} clips, ${g.kept_frames} of ${g.kept_frames + g.dropped_frames} frames (${g.leaf_edges} transitions)`];
  const shown = g.dropped.slice(0, 8);
  if (shown.length) lines.push(`left out (never played): ${shown.map((c) => `${c.clip} (${c.frames} frames): ${c.reason}`).join('; ')}${g.dropped.length > shown.length ? `; and ${g.dropped.length - shown.length} more` : ''}`);
  return { short: g.dropped.length ? `${g.dropped.length} left out` : '', long: lines.join('\n') };
}

// whether a database fits a picker: its kind, and for control databases what drives them
function fits(d, sel) {
  if (d.kind !== sel.dataset.kind || d.status !== 'ready') return false;
  return !sel.dataset.control || (d.summary && d.summary.control === sel.dataset.control);
}

let dbListSeq = 0;
let dbListSignature = '';
async function refreshDatabases() {
  const seq = ++dbListSeq;
  const databases = await api.databases();
  if (seq !== dbListSeq) return; // a newer refresh is on its way
  const signature = JSON.stringify(databases.map((d) => [d.id, d.status, d.frames, Boolean(d.summary)]));
  state.databases = databases;
  showWelcome();
  if (signature === dbListSignature) {
    clearStaleDatabaseErrors();
    return; // nothing changed: leave the lists (and open menus) alone
  }
  dbListSignature = signature;
  const list = $('db-list');
  list.textContent = '';
  for (const d of state.databases) {
    const li = document.createElement('li');
    li.dataset.db = d.id;
    li.innerHTML = '<span class="grow"></span><span></span><span class="muted mono"></span>';
    li.children[0].textContent = dbLabel(d);
    const kept = keptNote(d);
    li.children[0].title = `${d.id}\nclips: ${d.clips.join(', ')}${kept ? `\n${kept.long}` : ''}${d.error ? `\n${d.error}` : ''}`;
    li.children[1].textContent = d.status;
    li.children[1].className = `status-${d.status}`;
    li.children[2].textContent = [d.frames ? `${d.frames}f` : '', kept ? kept.short : ''].filter(Boolean).join(' · ');
    if (kept) li.children[2].title = kept.long;
    list.appendChild(li);
  }
  for (const sel of document.querySelectorAll('.db-select')) {
    const keep = sel.value;
    sel.textContent = '';
    const ready = state.databases.filter((d) => fits(d, sel));
    const building = state.databases.filter((d) => d.kind === sel.dataset.kind && ['queued', 'building'].includes(d.status));
    if (!ready.length) sel.add(new Option(building.length ? `(${dbLabel(building[building.length - 1])} is building…)` : sel.dataset.hint || `(build a ${sel.dataset.kind} database)`, ''));
    for (const d of ready.slice().reverse()) sel.add(new Option(`${dbLabel(d)} · ${d.clips.length} clip${d.clips.length === 1 ? '' : 's'}`, d.id));
    for (const d of building) {
      const o = new Option(`${dbLabel(d)} (building…)`, d.id);
      o.disabled = true;
      sel.add(o);
    }
    if (keep && ready.some((d) => d.id === keep)) sel.value = keep;
  }
  timeline.refreshTracks();
  tools.partner?.refreshLeaders();
  clearStaleDatabaseErrors();
}

// ---------------------------------------------------------------- first visit: "try it"
// An empty page (no clip, no database) offers the databases `segue demo ENGINE` builds, from
// bundled samples: one click builds one and opens the tool that uses it.
const welcome = { demos: [], shown: false, built: [] };
state.welcome = welcome;
function showWelcome() {
  welcome.shown = !state.databases.length && !state.clips.length && welcome.demos.length > 0;
  $('welcome').hidden = !welcome.shown;
}
async function loadDemos() {
  welcome.demos = await api.demos();
  const box = $('welcome-demos');
  box.textContent = '';
  for (const demo of welcome.demos) {
    const b = document.createElement('button');
    b.dataset.demo = demo.name;
    b.innerHTML = '<span></span><small></small>';
    b.firstChild.textContent = `${demo.tool}: ${demo.name}`;
    b.lastChild.textContent = demo.title;
    b.onclick = () => guarded('build', () => tryDemo(demo));
    box.appendChild(b);
  }
  showWelcome();
}
async function tryDemo(demo) {
  for (const b of $('welcome-demos').querySelectorAll('button')) b.disabled = true;
  try {
    const info = await buildDatabase({ ...demo.spec, name: `${demo.name} demo` });
    const tool = demo.tool.toLowerCase();
    welcome.built.push({ demo: demo.name, database: info.id, tool });
    selectTool(tool);
    const select = $(TOOL_SELECTS[tool]);
    if ([...select.options].some((o) => o.value === info.id)) {
      select.value = info.id;
      select.dispatchEvent(new Event('change'));
    }
  } finally {
    for (const b of $('welcome-demos').querySelectorAll('button')) b.disabled = false;
  }
}

const SPEC_TEMPLATES = {
  clips: { fps: 30 },
  graph: { fps: 30, tau: 1.0 },
  control: { fps: 30, segmentation: { method: 'beats', beats_per_segment: 2 } },
  annotated: { fps: 30 },
  rhythm: { beats_per_movement: 4 },
};
function fillSpecTemplate() {
  $('db-spec').value = JSON.stringify(SPEC_TEMPLATES[$('db-kind').value], null, 1);
}
$('db-kind').onchange = fillSpecTemplate;
fillSpecTemplate();

// a ticked clip in a spec: the uploaded clip's id, named as the clip list shows it
function clipRef(name) {
  const info = state.clips.find((c) => clipName(c) === name);
  return info ? { clip: info.id, name } : { bvh: name };
}

const LEADER = /leader|^60_/i;
const FOLLOWER = /follower|^61_/i;

// the spec to post: the JSON of the text box, with the ticked clips as `clips` (or as control
// `pairs`: a leader with a follower becomes one pair, any other clip a walk pair without a control)
export function composeSpec(kind, name, selected, text) {
  let extra;
  try {
    extra = text.trim() ? JSON.parse(text) : {};
  } catch (exc) {
    throw new ApiError(0, 'invalid_json', `the spec is not valid JSON: ${exc.message}`);
  }
  const spec = { ...extra, kind };
  if (name) spec.name = name;
  if (kind === 'control' && !spec.pairs) {
    const leaders = selected.filter((c) => LEADER.test(c));
    const followers = selected.filter((c) => FOLLOWER.test(c));
    const pairs = [];
    leaders.forEach((l, i) => { if (followers[i]) pairs.push({ control: l, target: followers[i] }); });
    for (const c of selected) if (!leaders.includes(c) && !followers.includes(c)) pairs.push({ control: null, target: c });
    if (!pairs.length && selected.length) throw new ApiError(0, 'invalid_request', 'tick a leader and a follower clip, or walk clips');
    spec.pairs = pairs.map((p) => ({ control: p.control && clipRef(p.control), target: clipRef(p.target) }));
    spec.clips = spec.clips || [];
  } else if (!spec.clips) {
    spec.clips = selected.map(clipRef);
  }
  if (kind === 'rhythm' && !spec.partners) {
    const leaders = selected.filter((c) => LEADER.test(c));
    const followers = selected.filter((c) => FOLLOWER.test(c));
    if (leaders.length && followers.length) spec.partners = [{ leader: leaders[0], follower: followers[0] }];
  }
  return spec;
}

export async function buildDatabase(spec) {
  return trackBuild(spec.kind, () => api.buildDatabase(spec));
}

// Start a build (`start()` posts it: a spec, or corrections) and follow it with progress to ready
async function trackBuild(kind, start) {
  const t0 = performance.now();
  const build = { kind, status: 'submitting', fraction: 0, message: '' };
  state.builds.push(build);
  let info;
  try {
    info = await start();
  } catch (exc) {
    build.status = 'refused';
    throw exc;
  }
  build.database = info.id;
  build.status = info.status === 'ready' ? 'found' : info.status;
  $('db-status').textContent = `${info.status}`;
  if (info.status === 'ready') {
    await refreshDatabases();
    build.status = 'ready';
    $('db-progress').value = 1;
    build.ms = performance.now() - t0;
    return info;
  }
  refreshDatabases();
  build.progress = []; // every progress event, as it came: (fraction, phase, message)
  const follow = followJob(info.build_job, (ev) => {
    if (ev.type === 'progress') {
      // the service's build progress: an overall fraction that only moves forward, its message
      // "phase: detail"
      const message = ev.data.message || '';
      const cut = message.indexOf(': ');
      build.fraction = ev.data.fraction;
      build.phase = cut > 0 ? message.slice(0, cut) : message;
      build.message = message;
      build.progress.push({ fraction: ev.data.fraction, phase: build.phase, message });
      $('db-progress').value = ev.data.fraction;
      $('db-status').textContent = `${Math.round(ev.data.fraction * 100)}% ${message}`;
    } else if (ev.type === 'started') {
      build.status = 'building';
      $('db-status').textContent = 'building';
    }
  });
  const last = await follow.done;
  const final = await api.database(info.id);
  await refreshDatabases();
  build.status = final.status;
  build.ms = performance.now() - t0;
  $('db-progress').value = final.status === 'ready' ? 1 : 0;
  $('db-status').textContent = final.status;
  if (last.type === 'failed' || final.status !== 'ready') {
    const msg = (last.data && last.data.error && last.data.error.message) || final.error || `build ${final.status}`;
    throw new ApiError(422, 'build_failed', msg);
  }
  return final;
}

$('db-build').onclick = () =>
  guarded('build', async () => {
    const selected = [...$('db-clips').querySelectorAll('input:checked')].map((i) => i.value);
    const spec = composeSpec($('db-kind').value, $('db-name').value.trim(), selected, $('db-spec').value);
    await buildDatabase(spec);
  });

// ---------------------------------------------------------------- jobs and solutions
let active = null; // the running tool's job: {tool, t0, jobId, handle}
let runSeq = 0; // bumped by every submission and by clearing: a submission answered late is dropped
let drawing = null; // the draw in flight
let pending = null; // the newest solution waiting for it: {run, sol}

// Draw solutions one at a time, newest wins: a better solution arriving while one downloads is
// drawn right after it (the first one is never abandoned, so it shows as early as possible).
function requestDraw(run, sol) {
  if (drawing) {
    pending = { run, sol };
    return drawing;
  }
  drawing = drawSolution(run, sol)
    .catch((exc) => showError(run.tool, exc))
    .finally(() => {
      drawing = null;
      if (pending) {
        const next = pending;
        pending = null;
        requestDraw(next.run, next.sol);
      }
    });
  return drawing;
}

// The database a tool's picker holds, or why there is none: one of its kind still building (with
// how far its build is), or none built yet.
function dbOf(selectId) {
  const sel = $(selectId);
  const id = sel.value;
  if (id) return id;
  const kind = sel.dataset.kind;
  // a build of this kind on its way: one the service lists, or one this page is submitting
  const listed = state.databases.filter((d) => d.kind === kind && ['queued', 'building'].includes(d.status));
  const mine = [...state.builds].reverse().find((b) => b.kind === kind && ['submitting', 'queued', 'building'].includes(b.status));
  if (listed.length || mine) {
    const d = listed.length ? listed[listed.length - 1] : state.databases.find((x) => mine && x.id === mine.database);
    const build = (d && [...state.builds].reverse().find((b) => b.database === d.id)) || mine;
    const progress = build && build.status === 'building' ? ` (${Math.round(build.fraction * 100)}%${build.phase ? `: ${build.phase}` : ''})` : '';
    const name = d ? ` ${dbLabel(d)}` : '';
    throw new ApiError(0, 'database_building', `the ${kind} database${name} is still building${progress}: this runs when it is ready`);
  }
  throw new ApiError(0, 'no_database', `choose a ready ${kind} database first (build one in the library)`);
}

// Submit a job for a tool; draw every better solution as it streams in (other characters, e.g.
// the leader, stay in the viewer). Resolves with the terminal event.
export async function runJob(tool, request) {
  if (active) {
    active.handle.stop();
    // a new request replaces the running one: free its worker
    if (state.job && !['done', 'failed', 'cancelled'].includes(state.job.status)) api.cancel(state.job.id).catch(() => {});
  }
  const t0 = performance.now();
  state.solutions = [];
  state.current = null;
  state.quality = null;
  $('sol-quality').hidden = true;
  $('alternatives').textContent = '';
  for (const id of ['dl-bvh', 'dl-glb']) $(id).disabled = true;
  $('sol-info').textContent = 'submitting…';
  state.shownTool = tool;
  const seq = ++runSeq;
  const info = await api.submit(request);
  if (seq !== runSeq) {
    // another tool was chosen (or another request made) while this one was on its way
    api.cancel(info.id).catch(() => {});
    return null;
  }
  state.job = { id: info.id, tool, status: info.status, submitted_ms: performance.now() - t0, events: [], reconnects: 0 };
  $('cancel-job').disabled = false;
  showJobState(state.job);
  let best = Infinity;
  const run = { tool, t0, jobId: info.id, db: request.database, request };
  active = run;
  run.handle = followJob(info.id, (ev) => {
    if (active !== run) return; // cleared, or replaced by another request
    state.job.events.push(ev.id);
    state.job.reconnects = run.handle ? run.handle.reconnects : 0;
    if (ev.type === 'progress') {
      $('sol-info').textContent = `${Math.round(ev.data.fraction * 100)}% ${ev.data.message || ''}`;
    } else if (ev.type === 'started') {
      state.job.status = 'running';
      showJobState(state.job);
    } else if (ev.type === 'solution' || ev.type === 'alternative') {
      // solutions are new bests (drawn as they come); alternatives are other candidates to pick
      const sol = { job: info.id, result: ev.data.result, score: ev.data.score, elapsed_ms: ev.data.elapsed_ms, terms: ev.data.terms, at_ms: performance.now() - t0,
        ok: ev.data.ok, reasons: ev.data.reasons || [], alternative: ev.type === 'alternative', frames: ev.data.frames, fps: ev.data.fps };
      state.solutions.push(sol);
      const mark = sol.ok === false ? ' · not ok' : '';
      const opt = new Option(`${sol.result} · ${sol.alternative ? 'alternative · ' : ''}score ${sol.score.toFixed(3)}${mark}`, sol.result);
      $('alternatives').add(opt);
      if (ev.type === 'solution' && sol.score < best) {
        best = sol.score;
        $('alternatives').value = sol.result;
        requestDraw(run, sol);
      }
    } else if (['done', 'failed', 'cancelled'].includes(ev.type)) {
      state.job.status = ev.type;
      const error = ev.data.error || {};
      state.job.end = { type: ev.type, result: ev.data.result || null, stopped: ev.data.stopped || null, short: ev.data.short || null,
        message: ev.type === 'failed' ? `${error.message || 'the job failed'} [${error.code || 'failed'}]` : ev.data.message || '' };
      showJobState(state.job);
      $('cancel-job').disabled = true;
      flushBody();
      if (ev.type === 'failed') showError(tool, new ApiError(422, ev.data.error.code, ev.data.error.message));
      if (!state.solutions.length && ev.type !== 'failed') $('sol-info').textContent = `${ev.type} without a result`;
    }
  });
  active = run;
  const last = await run.handle.done;
  return last;
}

async function drawSolution(run, sol) {
  const tFetch = performance.now();
  // BVH is the quickest format to export and to load (a 2,000-frame result: ~0.2 s vs ~1 s for JSON
  // frames); result motions are in metres (target gltf). The viewer draws at most 30 fps, so a
  // 120 fps dance downloads a quarter of the frames (downloads keep the full rate)
  const bytes = await (await api.resultBlob(sol.job, sol.result, 'bvh', VIEW_FPS)).arrayBuffer();
  if (active !== run) return; // another job started meanwhile
  const tParse = performance.now();
  const motion = parseBvhText(await bvhText(bytes), `${run.tool} ${sol.result}`);
  const tDraw = performance.now();
  const first = !state.current;
  // the ring and trail follow the body: the hips the database's summary names (not a static root)
  const summary = summaryOf(run.db);
  const root = placeJoint(motion, summary && summary.skeleton.hips);
  viewer.set('result', motion, undefined, { root }); // framed: each better solution may go elsewhere
  const drawn = performance.now() - run.t0;
  // the result as computed (its report's frames and rate, which its reasons count in), and the
  // preview drawn here (at most VIEW_FPS)
  const sourceFrames = sol.frames ?? motion.frames;
  const sourceFps = sol.fps ?? motion.fps;
  state.current = { tool: run.tool, job: sol.job, result: sol.result, score: sol.score, frames: motion.frames, fps: motion.fps, source_frames: sourceFrames, source_fps: sourceFps, joints: motion.joints.length, drawn_ms: drawn, root: rootPath(motion, root),
    rootJoint: motion.joints[root],
    // where the time went: the event's arrival, the download, parsing, drawing (ms)
    event_ms: sol.at_ms, download_ms: tParse - tFetch, parse_ms: tDraw - tParse, draw_ms: performance.now() - tDraw };
  if (state.timings[run.tool] === undefined || first) {
    state.timings[run.tool] = drawn;
    const { event_ms, download_ms, parse_ms, draw_ms } = state.current;
    state.firstDraw[run.tool] = { drawn_ms: drawn, event_ms, download_ms, parse_ms, draw_ms, result: sol.result };
  }
  $('sol-info').textContent = `${sol.result} · score ${sol.score.toFixed(3)} · found at ${(sol.elapsed_ms / 1000).toFixed(2)} s · ${framesText(sourceFrames, sourceFps, motion)}`;
  showQuality(sol);
  for (const id of ['dl-bvh', 'dl-glb']) $(id).disabled = false;
  if (first) { viewer.seek(0); viewer.play(); }
  tools[run.tool]?.onResult?.(motion, root);
  // the body (the picked character, or the mannequin) and the goals, once the service has them
  settleBody(run, () => characters.show('result', { kind: 'result', job: sol.job, result: sol.result, motion, hips: motion.joints[root] }));
  showGoals(run, sol, motion, root).catch((exc) => showError(run.tool, exc));
}

// A running search may find a better solution every few hundred ms: its body (a GLB the service
// exports, parsed and measured here) is fetched once the solutions settle (BODY_SETTLE_MS without
// a better one) or the job ends, not for every one; the stick figure shows each at once.
const BODY_SETTLE_MS = 500;
let bodyPending = null; // {timer, load}
function settleBody(run, load) {
  if (bodyPending) clearTimeout(bodyPending.timer);
  const running = state.job && !['done', 'failed', 'cancelled'].includes(state.job.status);
  const fire = () => { bodyPending = null; if (active === run) load(); };
  if (!running) { bodyPending = null; load(); return; }
  bodyPending = { timer: setTimeout(fire, BODY_SETTLE_MS), fire };
}
function flushBody() {
  if (!bodyPending) return;
  clearTimeout(bodyPending.timer);
  bodyPending.fire();
}

// The request's goals drawn where they were asked, met or missed as the result's report says
// (its constraint_errors): body arrows (Constraints), the follower's spots (Partner), the path
// (Path); a missed one with a line to where the body was at its frame.
async function showGoals(run, sol, motion, root) {
  const req = run.request;
  const wanted = [];
  if (Array.isArray(req.constraints)) {
    req.constraints.forEach((c, i) => { if (c.type === 'body') wanted.push({ name: `body[${i}]`, frame: c.frame, position: c.position, heading_deg: c.heading_deg }); });
  }
  if (Array.isArray(req.bodies)) {
    req.bodies.forEach((b, i) => wanted.push({ name: `body[${i}]`, frame: Math.round(b.time_s * motion.fps), position: b.position }));
  }
  const path = req.control && req.control.trajectory ? req.control.trajectory.points : null;
  if (!wanted.length && !path) { viewer.setGoals(null); return; }
  const report = await api.report(sol.job, sol.result);
  if (active !== run || !state.current || state.current.result !== sol.result) return;
  const errors = report.constraint_errors || {};
  const J = motion.joints.length;
  const at = (frame) => {
    const f = Math.min(Math.max(frame ?? 0, 0), motion.frames - 1);
    return [motion.positions[(f * J + root) * 3], motion.positions[(f * J + root) * 3 + 2]];
  };
  const goals = wanted.map((g) => {
    const e = errors[g.name] || {};
    const frame = e.frame ?? g.frame;
    return { ...g, met: e.satisfied, reached: at(Math.round((frame * motion.fps) / (sol.fps || motion.fps))), error_cm: e.position_cm };
  });
  if (path && path.length > 1) {
    const e = errors.path || {};
    goals.push({ name: 'path', position: path[0], met: e.satisfied });
    goals.push({ name: 'path', position: path[path.length - 1], met: e.satisfied });
  }
  viewer.setGoals(goals);
  state.goals = goals.map(({ name, position, met, error_cm }) => ({ name, position, met, error_cm }));
}

// Where the job stands, in words beside Cancel: queued, running, then how it ended (done,
// cancelled or failed, with the supervisor's `stopped` reason and a shortfall when the event has them)
function showJobState(job) {
  const el = $('job-state');
  if (!job) { el.hidden = true; el.textContent = ''; return; }
  const end = job.end;
  let text = { queued: 'queued…', running: 'running…' }[job.status] || job.status;
  if (end) {
    const best = end.result ? ` · best ${end.result}` : '';
    // the best result's quality verdict, as its report says (the badge has its reasons)
    const sol = end.result ? state.solutions.find((x) => x.result === end.result) : null;
    const verdict = sol && sol.ok !== undefined && sol.ok !== null ? ` · ${sol.ok ? 'ok' : 'not ok'}` : '';
    const stopped = end.stopped ? ` · stopped: ${end.stopped}` : '';
    const short = end.short ? ` · short: ${end.short.frames} of ${end.short.requested_frames} frames` : '';
    text = end.type === 'failed' ? `failed: ${end.message}` : `${end.type}${best}${verdict}${stopped}${short}`;
    if (!end.result && end.type !== 'failed') text = `${end.type} without a result`;
  }
  el.hidden = false;
  el.className = `job-state ${job.status}`;
  el.textContent = text;
  el.title = end && end.message ? end.message : '';
  job.label = text;
  job.labels = [...(job.labels || []), text]; // every state shown, for tests
}

// The result's quality report in one badge: "ok", or "not ok" with the first reason (all on hover).
function showQuality(sol) {
  const el = $('sol-quality');
  if (sol.ok === undefined || sol.ok === null) { el.hidden = true; return; }
  el.hidden = false;
  el.className = `quality ${sol.ok ? 'ok' : 'bad'}`;
  el.textContent = sol.ok ? 'ok' : `not ok: ${sol.reasons[0] || ''}${sol.reasons.length > 1 ? ` (+${sol.reasons.length - 1})` : ''}`;
  el.title = sol.ok ? 'every constraint met; as plausible as the database\'s examples' : sol.reasons.join('\n');
  state.quality = { result: sol.result, ok: sol.ok, reasons: sol.reasons };
}

// a frame rate as people write it (a BVH's frame time rounds 30 fps to 30.0003)
const rate = (fps) => (Math.abs(fps - Math.round(fps)) < 0.01 ? String(Math.round(fps)) : fps.toFixed(2));
// "260 frames at 60 fps (drawn at 30 fps)": the result's own frames (the ones its report's reasons
// name), and the preview's rate when the page draws fewer
export function framesText(frames, fps, preview) {
  const drawn = preview && Math.abs(preview.fps - fps) > 0.01 ? ` (drawn at ${rate(preview.fps)} fps)` : '';
  return `${frames} frames at ${rate(fps)} fps${drawn}`;
}

// the floor path [[x, z], ...] of a motion's place joint (the hips; see viewer.placeJoint)
function rootPath(motion, root = placeJoint(motion)) {
  const J = motion.joints.length;
  const out = [];
  for (let f = 0; f < motion.frames; f++) out.push([motion.positions[(f * J + root) * 3], motion.positions[(f * J + root) * 3 + 2]]);
  return out;
}

$('alternatives').onchange = () =>
  guarded('download', async () => {
    const sol = state.solutions.find((s) => s.result === $('alternatives').value);
    if (sol && active) await requestDraw(active, sol);
  });

$('cancel-job').onclick = () => guarded('download', async () => { if (state.job) await api.cancel(state.job.id); });

async function download(format) {
  if (!state.current || !state.current.job) throw new ApiError(0, 'no_result', 'no result to download yet');
  const { job, result } = state.current;
  const character = $('character').value;
  const feet = $('feet').value;
  const blob = await api.resultBlob(job, result, format, undefined, character, undefined, undefined, feet);
  const record = { format, job, result, bytes: blob.size, character, feet };
  if (format === 'glb') {
    // check the file the service made: it must load in three.js with its animation
    const gltf = await new GLTFLoader().parseAsync(await blob.arrayBuffer(), '');
    record.animations = gltf.animations.length;
    record.duration_s = gltf.animations.length ? gltf.animations[0].duration : 0;
  } else {
    const text = await blob.text();
    record.frames = Number((text.match(/Frames:\s*(\d+)/) || [])[1] || 0);
  }
  state.downloads.push(record);
  const a = document.createElement('a');
  a.href = URL.createObjectURL(blob);
  a.download = `segue-${job.slice(0, 8)}-${result}.${format}`;
  document.body.appendChild(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(a.href), 10000);
}
$('dl-bvh').onclick = () => guarded('download', () => download('bvh'));
$('dl-glb').onclick = () => guarded('download', () => download('glb'));

// ---------------------------------------------------------------- tools
const tools = {};

for (const b of document.querySelectorAll('#tabs button')) {
  b.onclick = () => selectTool(b.dataset.tool);
}
// Each tool shows only its own results: switching tools stops following another tool's job (and
// cancels it when it still runs) and clears its drawing, its solutions and its quality badge.
// what the download and cancel buttons say while they cannot act
function explainButtons() {
  for (const id of ['dl-bvh', 'dl-glb']) $(id).title = $(id).disabled ? 'no result to download yet: run a tool (a clip is downloaded as uploaded)' : `download the shown result (${id === 'dl-glb' ? 'GLB' : 'BVH'}) on the chosen character`;
  $('cancel-job').title = $('cancel-job').disabled ? 'no job running' : 'stop the job (its best result so far stays)';
}
new MutationObserver(explainButtons).observe($('solution-bar'), { attributes: true, subtree: true, attributeFilter: ['disabled'] });
explainButtons();

function clearResults() {
  runSeq += 1; // a submission on its way is cancelled when it returns
  if (bodyPending) { clearTimeout(bodyPending.timer); bodyPending = null; }
  if (active) {
    active.handle.stop();
    if (state.job && !['done', 'failed', 'cancelled'].includes(state.job.status)) api.cancel(state.job.id).catch(() => {});
    active = null;
  }
  pending = null;
  for (const t of Object.values(tools)) t.stopLive?.();
  viewer.clear();
  state.job = null;
  state.goals = null;
  state.shownTool = null;
  state.current = null;
  state.solutions = [];
  state.quality = null;
  $('sol-quality').hidden = true;
  $('alternatives').textContent = '';
  for (const id of ['dl-bvh', 'dl-glb']) $(id).disabled = true;
  $('cancel-job').disabled = true;
  showJobState(null);
  $('sol-info').textContent = 'no result yet';
  for (const t of Object.values(tools)) t.clearResult?.();
}

// The solution bar, the job state and the viewer belong to the tool that made them
// (state.shownTool: a job, a live session, or 'library' for a clip): any other tool starts clear.
export function selectTool(name) {
  if (name !== state.tool && state.shownTool && state.shownTool !== 'library' && state.shownTool !== name) clearResults();
  state.tool = name;
  for (const b of document.querySelectorAll('#tabs button')) b.classList.toggle('active', b.dataset.tool === name);
  for (const t of document.querySelectorAll('.tool')) t.classList.toggle('active', t.id === `tool-${name}`);
  tools[name]?.redraw?.();
  tools[name]?.onShow?.();
}

function numberOf(id, where, lo, hi) {
  const v = Number($(id).value);
  if (!Number.isFinite(v) || v < lo || v > hi) throw new ApiError(0, 'invalid_input', `${where}: give a number from ${lo} to ${hi}`);
  return v;
}

// -- Path: a performed mouse path, sampled at 30 Hz with its timing -> control engine walk
tools.path = (() => {
  const pad = new FloorPad($('path-pad'), 5);
  const canvas = $('path-pad');
  let result = [];
  const redraw = () => {
    const ctx = pad.clear();
    const pts = state.path.points;
    if (result.length) pad.polyline(ctx, result, '#f0a030', 2);
    pad.polyline(ctx, pts, '#4aa3ff', 2);
    // the user's position every second, and where a walker at the reference speed would be
    const ref = Number($('path-ref').value) || 1.3;
    let acc = 0;
    let next = ref;
    for (let i = 1; i < pts.length; i++) {
      const seg = Math.hypot(pts[i][0] - pts[i - 1][0], pts[i][1] - pts[i - 1][1]);
      while (acc + seg >= next && seg > 0) {
        const u = (next - acc) / seg;
        pad.dot(ctx, [pts[i - 1][0] + u * (pts[i][0] - pts[i - 1][0]), pts[i - 1][1] + u * (pts[i][1] - pts[i - 1][1])], '#7ccf7c', 3);
        next += ref;
      }
      acc += seg;
      if (i % 30 === 0) pad.dot(ctx, pts[i], '#ffffff', 2.5);
    }
    if (pts.length) pad.dot(ctx, pts[0], '#4aa3ff', 5);
    const secs = pts.length > 1 ? (pts.length - 1) / 30 : 0;
    $('path-info').textContent = pts.length > 1
      ? `${pts.length} samples · ${secs.toFixed(2)} s · ${acc.toFixed(2)} m · ${(acc / secs).toFixed(2)} m/s (ref ${ref} m/s)`
      : 'no path';
  };
  // The pointer's positions with their times (ms), resampled at exactly 30 Hz by linear
  // interpolation: the path keeps the performance's timing whatever the event and timer jitter.
  let raw = null;
  let timer = null;
  const resample = (until, fps = 30) => {
    const t0 = raw[0][0];
    const n = Math.floor(((until - t0) / 1000) * fps) + 1;
    const out = [];
    let k = 0;
    for (let i = 0; i < n; i++) {
      const t = t0 + (i * 1000) / fps;
      while (k + 1 < raw.length && raw[k + 1][0] <= t) k++;
      const a = raw[k];
      const b = raw[Math.min(k + 1, raw.length - 1)];
      const u = b[0] > a[0] ? Math.min(Math.max((t - a[0]) / (b[0] - a[0]), 0), 1) : 0;
      out.push([a[1] + u * (b[1] - a[1]), a[2] + u * (b[2] - a[2])]);
    }
    return out;
  };
  const record = (ev) => {
    const [x, z] = pad.toFloor(ev.clientX, ev.clientY);
    raw.push([performance.now(), x, z]);
  };
  // live mode: the path streams to the live control session while it is drawn (livewalk.js)
  let live = null;
  const startLive = () => {
    const database = dbOf('path-db');
    const latencyS = numberOf('path-latency', 'latency', 0.5, 5);
    if (live) live.close();
    clearResults();
    state.shownTool = 'path';
    let first = true;
    const t0 = performance.now();
    live = startLiveWalk({
      database,
      latencyS,
      ApiError,
      onStatus: (text) => { $('sol-info').textContent = text; },
      onFrames: (positions, frames, fps, names, parents, rotations, offsets) => {
        viewer.loop = false;
        viewer.follow = 'result';
        const motion = { name: 'live walk', fps, joints: names, parents, frames, positions, rotations, offsets: new Float32Array(offsets.flat()) };
        viewer.set('result', motion, undefined, { frame: first });
        characters.live('result', motion);
        const J = names.length;
        result = [];
        for (let f = 0; f < frames; f++) result.push([positions[f * J * 3], positions[f * J * 3 + 2]]);
        state.current = { tool: 'path', live: true, frames, fps, root: result };
        if (first) {
          state.timings.path_live = performance.now() - t0;
          viewer.seek(0);
          viewer.play();
          first = false;
        }
        redraw();
      },
    });
    state.pathLive = live.info;
    const session = live;
    guarded('path', async () => {
      try {
        await session.done;
      } finally {
        viewer.loop = true;
        viewer.follow = null;
        if (live === session) live = null;
      }
    });
  };
  canvas.addEventListener('pointerdown', (ev) => {
    if ($('path-live').checked) {
      clearError('path');
      try {
        startLive();
      } catch (exc) {
        showError('path', exc);
        return;
      }
    }
    canvas.setPointerCapture(ev.pointerId);
    raw = [];
    record(ev);
    result = [];
    clearInterval(timer);
    timer = setInterval(() => {
      const now = performance.now();
      state.path.points = resample(now);
      if (live && live.fps()) live.push(resample(now, live.fps()));
      redraw();
    }, 1000 / 30);
  });
  canvas.addEventListener('pointermove', (ev) => {
    if (!timer) return;
    // the pointer rested since its last event (held when events are sparse)
    const last = raw[raw.length - 1];
    if (performance.now() - last[0] > 50) raw.push([performance.now() - 1e-3, last[1], last[2]]);
    record(ev);
  });
  const stop = () => {
    if (!timer) return;
    clearInterval(timer);
    timer = null;
    const until = performance.now();
    state.path.points = resample(until);
    state.path.held_ms = until - raw[0][0]; // how long the button was held, as the page timed it
    if (live) {
      // the whole path, at the session's fps once known (a busy server may open the session only
      // after the button is released: the path drawn meanwhile is sent then, not lost)
      live.stop((fps) => resample(until, fps));
    }
    redraw();
  };
  canvas.addEventListener('pointerup', stop);
  canvas.addEventListener('pointercancel', stop);
  $('path-clear').onclick = () => { state.path.points = []; result = []; redraw(); };
  $('path-ref').oninput = redraw;
  $('path-go').onclick = () =>
    guarded('path', async () => {
      const db = dbOf('path-db');
      const pts = state.path.points;
      if (pts.length < 2) throw new ApiError(0, 'no_path', 'draw a path first (hold the mouse button and move)');
      const smoothing = Number($('path-smooth').value);
      viewer.clear();
      await runJob('path', {
        engine: 'control',
        database: db,
        budget_s: numberOf('path-budget', 'budget', 0.1, 600),
        control: { trajectory: { fps: 30, points: pts.map(([x, z]) => [+x.toFixed(4), +z.toFixed(4)]), smoothing: { temporal_s: smoothing } } },
      });
    });
  redraw();
  return {
    redraw,
    onResult: (motion, root) => { result = rootPath(motion, root); redraw(); },
    clearResult: () => { result = []; redraw(); },
    stopLive: () => { if (live) { live.close(); live = null; } },
  };
})();

// -- Partner: a leader clip -> the follower (control engine with the leader as the control motion)
tools.partner = (() => {
  // the follower's start and end spots (request `bodies`), clicked on a floor pad beside the
  // leader's path: the first click is the start, the second the end (later clicks move the end);
  // after a result, its start and end are offered (hollow rings) and a click moves the nearer one
  const pad = new FloorPad($('partner-pad'), 3);
  const canvas = $('partner-pad');
  let leaderPath = [];
  let result = [];
  let shownLeader = null; // the picker value whose path is drawn
  let leaderLoading = false;
  state.partner = { spots: [], bodies: null, offered: null, leaders: [], drawn: null };
  // test hook: where a floor point [x, z] is on the pad, as fractions of its width and height
  state.partner.padFraction = (p) => { const [x, y] = pad.toPixels(p); return [x / canvas.width, y / canvas.height]; };
  const info = (name) => state.clips.find((c) => clipName(c) === name);
  const sampleFile = (name) => Object.keys(state.samples).find((f) => state.samples[f] === name);
  // the words of a clip's name that say what it is (not its numbers): "60_12_salsa_leader_30fps"
  // -> salsa, leader
  const words = (name) => new Set(String(name).toLowerCase().replace(/\.gz$/, '').replace(/\.bvh$/, '')
    .split(/[^a-z0-9]+/).filter((w) => w && !/^\d/.test(w)));
  // The leaders that fit the chosen database: its skeleton (uploaded clips; a bundled sample is
  // checked once drawn), named like its control clips (the words all their names share), not one
  // of its followers; those it was not built from first ("held out"), then its own leaders.
  const fittingLeaders = () => {
    const summary = summaryOf($('partner-db').value);
    if (!summary) return [];
    const inDb = new Set(summary.clips.map((c) => c.name));
    const targets = new Set(summary.clips.filter((c) => c.role === 'target').map((c) => c.name));
    const controls = summary.clips.filter((c) => c.role === 'control').map((c) => words(c.name));
    const common = controls.length ? [...controls[0]].filter((w) => controls.every((ws) => ws.has(w))) : [];
    const named = (aliases) => aliases.some((a) => { const ws = words(a); return common.every((w) => ws.has(w)); });
    const joints = summary.skeleton.joints.join('\n');
    const out = [];
    const uploadedSamples = new Set();
    for (const c of state.clips) {
      const aliases = [clipName(c), state.samples[c.name]].filter(Boolean);
      if (state.samples[c.name]) uploadedSamples.add(state.samples[c.name]);
      if (c.joints.join('\n') !== joints || aliases.some((a) => targets.has(a)) || !named(aliases)) continue;
      out.push({ value: clipName(c), label: clipName(c), heldOut: !aliases.some((a) => inDb.has(a)) });
    }
    for (const name of Object.values(state.samples)) {
      if (uploadedSamples.has(name) || targets.has(name) || !named([name])) continue;
      out.push({ value: `sample:${name}`, label: `${name} (bundled sample)`, heldOut: !inDb.has(name) });
    }
    return [...out.filter((l) => l.heldOut), ...out.filter((l) => !l.heldOut)];
  };
  const refreshLeaders = () => {
    const sel = $('partner-clip');
    const keep = sel.value;
    const leaders = fittingLeaders();
    state.partner.leaders = leaders;
    sel.textContent = '';
    if (!leaders.length) {
      const db = $('partner-db').value;
      sel.add(new Option(db ? '(no clip fits this database: upload a leader with its skeleton)' : '(choose a partner database)', ''));
    }
    for (const l of leaders) sel.add(new Option(l.heldOut ? l.label : `${l.label} (in the database)`, l.value));
    // keep the user's pick when it still fits; else the first held-out leader
    if (keep && leaders.some((l) => l.value === keep)) sel.value = keep;
    else if (keep.startsWith('sample:') && leaders.some((l) => l.value === clipName({ name: sampleFile(keep.slice(7)) || '' }))) {
      sel.value = clipName({ name: sampleFile(keep.slice(7)) });
    }
    if (state.tool === 'partner' && !leaderLoading && sel.value !== shownLeader) guarded('partner', showLeader);
  };
  // a bundled sample picked as the leader is uploaded (as the library's Upload does): the request
  // names it, the page draws it in the units the API found for it
  const ensureLeader = async (value) => {
    if (!value.startsWith('sample:')) return value;
    const file = sampleFile(value.slice(7));
    if (!file) throw new ApiError(0, 'no_clip', `no bundled sample ${value}`);
    const uploaded = await api.uploadClip(file, await api.sampleBytes(file));
    await refreshClips();
    const name = clipName(uploaded);
    $('partner-clip').value = name;
    return name;
  };
  // the leader in metres: parsed in this page when it was uploaded here, else its bytes from the
  // API (GET /v1/clips/{id}/bvh: clips uploaded by any client); null when it is not a clip
  const leaderMotion = async (name) => {
    let motion = clipMotions.get(name);
    const c = info(name);
    if (!motion && c) {
      const scale = METRES_PER_UNIT[c.units] || 1;
      motion = parseBvhText(await bvhText(await api.clipBytes(c.id, readByService(c))), name, scale);
      clipMotions.set(name, motion);
    }
    return motion || null;
  };
  const ring = (ctx, p, color) => {
    const [x, y] = pad.toPixels(p);
    ctx.strokeStyle = color;
    ctx.lineWidth = 2;
    ctx.beginPath(); ctx.arc(x, y, 7, 0, 2 * Math.PI); ctx.stroke();
  };
  const at = (p) => `[${p[0].toFixed(2)}, ${p[1].toFixed(2)}]`;
  const redraw = () => {
    const ctx = pad.clear();
    if (leaderPath.length) {
      pad.polyline(ctx, leaderPath, '#4aa3ff', 2);
      pad.dot(ctx, leaderPath[0], '#4aa3ff', 4);
    }
    if (result.length) pad.polyline(ctx, result, '#f0a030', 2);
    const { spots, offered } = state.partner;
    if (!spots.length && offered) offered.forEach((p, i) => ring(ctx, p, i ? '#e06060' : '#7ccf7c'));
    spots.forEach((p, i) => pad.dot(ctx, p, i ? '#e06060' : '#7ccf7c', 6));
    const [a, b] = spots;
    let text = 'no spots';
    if (a) text = `start ${at(a)}${b ? ` · end ${at(b)}` : ''} m`;
    else if (offered) text = `follower starts ${at(offered[0])} · ends ${at(offered[1])} m (click near one to move it)`;
    $('partner-spots-info').textContent = text;
  };
  const showLeader = async () => {
    const value = $('partner-clip').value;
    shownLeader = value;
    leaderLoading = true;
    let name = '';
    try {
      name = value ? await ensureLeader(value) : '';
    } finally {
      leaderLoading = false;
    }
    shownLeader = $('partner-clip').value;
    const motion = name ? await leaderMotion(name) : null;
    const summary = summaryOf($('partner-db').value);
    const joints = motion ? skeletonJoints(motion) : [];
    if (motion && summary && joints.join('\n') !== summary.skeleton.joints.join('\n')) {
      throw new ApiError(0, 'wrong_skeleton', `the leader ${name} has another skeleton than the database's (${joints.length} joints, not ${summary.skeleton.joints.length})`);
    }
    leaderPath = motion ? rootPath(motion) : [];
    state.partner.drawn = motion ? name : null; // the leader on the pad (tests wait on it)
    if (leaderPath.length) {
      const mean = (k) => leaderPath.reduce((acc, p) => acc + p[k], 0) / leaderPath.length;
      pad.center = [mean(0), mean(1)];
    }
    redraw();
  };
  $('partner-clip').addEventListener('change', () => guarded('partner', showLeader));
  $('partner-db').addEventListener('change', () => { state.partner.offered = null; refreshLeaders(); });
  canvas.addEventListener('click', (ev) => {
    const { spots, offered } = state.partner;
    const p = pad.toFloor(ev.clientX, ev.clientY);
    if (!spots.length && offered) {
      // start from the offered spots: the click moves the nearer one
      spots.push([...offered[0]], [...offered[1]]);
      const d = (q) => Math.hypot(q[0] - p[0], q[1] - p[1]);
      spots[d(offered[0]) <= d(offered[1]) ? 0 : 1] = p;
    } else if (spots.length < 2) spots.push(p);
    else spots[1] = p;
    redraw();
  });
  $('partner-spots-clear').onclick = () => { state.partner.spots = []; redraw(); };
  $('partner-go').onclick = () =>
    guarded('partner', async () => {
      const db = dbOf('partner-db');
      const picked = $('partner-clip').value;
      if (!picked) throw new ApiError(0, 'no_clip', 'upload a leader clip that fits this database first');
      const leader = await ensureLeader(picked);
      viewer.clear();
      const c = info(leader);
      const request = { engine: 'control', database: db, budget_s: numberOf('partner-budget', 'budget', 0.1, 600), control: { bvh: c ? c.name : leader } };
      const spots = state.partner.spots;
      if (spots.length) {
        // the control's length, for the end spot: the clip's frames at its rate, as the API lists it
        const length = c ? (c.frames - 1) / c.fps : null;
        if (length === null) throw new ApiError(0, 'no_length', 'the leader is not an uploaded clip: its length (for the end spot) is unknown');
        const place = (p) => [+p[0].toFixed(4), +p[1].toFixed(4)];
        request.bodies = [{ time_s: 0, position: place(spots[0]) }];
        if (spots[1]) request.bodies.push({ time_s: Math.floor(length * 1000) / 1000, position: place(spots[1]) });
      }
      state.partner.bodies = request.bodies || null;
      state.partner.leader = leader;
      const job = runJob('partner', request);
      const motion = await leaderMotion(leader);
      if (motion) {
        viewer.set('leader', motion, undefined, { frame: !viewer.has('result') });
        characters.show('leader', { kind: 'motion', motion, hips: motion.joints[placeJoint(motion)] });
      } else {
        $('err-partner').textContent = `(the leader ${leader} is not an uploaded clip: it is not drawn)`;
      }
      await job;
    });
  redraw();
  return {
    redraw,
    refreshLeaders,
    onShow: () => { if (!leaderLoading && $('partner-clip').value !== shownLeader) guarded('partner', showLeader); },
    onResult: (motion, root) => {
      result = rootPath(motion, root);
      state.partner.offered = result.length ? [result[0], result[result.length - 1]] : null;
      redraw();
    },
    clearResult: () => { result = []; state.partner.offered = null; redraw(); },
  };
})();

// -- Constraints: body arrows (position + heading) and a length -> graph search with alternatives
tools.constraints = (() => {
  const pad = new FloorPad($('cons-pad'), 5);
  const canvas = $('cons-pad');
  let dragging = null;
  let result = [];
  const frameCount = () => {
    const db = state.databases.find((d) => d.id === $('cons-db').value);
    const fps = (db && db.fps) || 30;
    return Math.max(2, Math.round(numberOf('cons-length', 'length', 0.2, 3600) * fps));
  };
  const fps = () => {
    const db = state.databases.find((d) => d.id === $('cons-db').value);
    return (db && db.fps) || 30;
  };
  // each arrow's output frame: its own time when given, else evenly spaced from first to last frame
  const frames = (n, F) =>
    state.constraints.slice(0, n).map((c, i) => {
      if (c.time_s !== undefined && c.time_s !== null) return Math.min(F - 1, Math.max(0, Math.round(c.time_s * fps())));
      return n === 1 ? 0 : Math.round((i * (F - 1)) / (n - 1));
    });
  const redraw = () => {
    const ctx = pad.clear();
    if (result.length) pad.polyline(ctx, result, '#f0a030', 2);
    let F = 180;
    try { F = frameCount(); } catch { /* shown on submit */ }
    const at = frames(state.constraints.length, F);
    state.constraints.forEach((c, i) => pad.arrow(ctx, c.position, c.heading_deg, i === 0 ? '#7ccf7c' : '#4aa3ff', `${i + 1}: f${at[i]}`));
    const list = $('cons-list');
    list.textContent = '';
    state.constraints.forEach((c, i) => {
      const li = document.createElement('li');
      li.innerHTML = '<span class="grow"></span><label>at <input type="number" step="0.1" min="0"> s</label>';
      li.firstChild.textContent = `frame ${at[i]} · [${c.position.map((v) => v.toFixed(2)).join(', ')}] m · ${c.heading_deg.toFixed(0)}°`;
      const input = li.querySelector('input');
      input.value = (at[i] / fps()).toFixed(2);
      input.title = 'time of this arrow (seconds); empty: evenly spaced';
      input.onchange = () => {
        c.time_s = input.value === '' ? null : Math.max(0, Number(input.value));
        redraw();
      };
      list.appendChild(li);
    });
  };
  canvas.addEventListener('contextmenu', (ev) => {
    // right click: remove the nearest arrow (within 0.5 m)
    ev.preventDefault();
    const [x, z] = pad.toFloor(ev.clientX, ev.clientY);
    let best = -1;
    let bestD = 0.5;
    state.constraints.forEach((c, i) => {
      const d = Math.hypot(c.position[0] - x, c.position[1] - z);
      if (d < bestD) { best = i; bestD = d; }
    });
    if (best >= 0) state.constraints.splice(best, 1);
    redraw();
  });
  canvas.addEventListener('pointerdown', (ev) => {
    if (ev.button !== 0) return;
    canvas.setPointerCapture(ev.pointerId);
    dragging = { position: pad.toFloor(ev.clientX, ev.clientY), heading_deg: 0 };
    state.constraints.push(dragging);
    redraw();
  });
  canvas.addEventListener('pointermove', (ev) => {
    if (!dragging) return;
    const [x, z] = pad.toFloor(ev.clientX, ev.clientY);
    const dx = x - dragging.position[0];
    const dz = z - dragging.position[1];
    if (Math.hypot(dx, dz) > 0.1) dragging.heading_deg = headingDeg(dx, dz);
    redraw();
  });
  canvas.addEventListener('pointerup', () => { dragging = null; redraw(); });
  $('cons-clear').onclick = () => { state.constraints = []; result = []; redraw(); };
  $('cons-length').oninput = redraw;
  $('cons-go').onclick = () =>
    guarded('constraints', async () => {
      const db = dbOf('cons-db');
      if (!state.constraints.length) throw new ApiError(0, 'no_constraints', 'place at least one body arrow first: click the pad where the body should be, drag to aim it');
      const F = frameCount();
      const at = frames(state.constraints.length, F);
      viewer.clear();
      await runJob('constraints', {
        engine: 'graph',
        database: db,
        frames: F,
        alternatives: Math.round(numberOf('cons-alts', 'alternatives', 1, 20)),
        budget_s: numberOf('cons-budget', 'budget', 0.1, 600),
        constraints: state.constraints.map((c, i) => ({ type: 'body', frame: at[i], position: c.position.map((v) => +v.toFixed(3)), heading_deg: +c.heading_deg.toFixed(1) })),
      });
    });
  redraw();
  return { redraw, onResult: (motion, root) => { result = rootPath(motion, root); redraw(); }, clearResult: () => { result = []; redraw(); } };
})();

// -- Timeline: paint do / don't per label track -> annotation synthesis; label corrections
timeline = tools.timeline = (() => {
  const canvas = $('tl-canvas');
  const tl = state.timeline;
  let painting = null;
  const nFrames = () => Math.max(2, Math.round(Number($('tl-frames').value) || 300));
  const ensure = () => {
    const F = nFrames();
    for (const t of tl.tracks) if (t.values.length !== F) {
      const v = new Int8Array(F);
      v.set(t.values.subarray(0, F));
      t.values = v;
    }
  };
  const rowH = 24;
  const labelW = 70;
  const redraw = () => {
    ensure();
    canvas.height = Math.max(1, tl.tracks.length) * rowH + 16;
    const ctx = canvas.getContext('2d');
    const w = canvas.width - labelW;
    ctx.fillStyle = '#1d2127';
    ctx.fillRect(0, 0, canvas.width, canvas.height);
    const F = nFrames();
    tl.tracks.forEach((t, r) => {
      const y = r * rowH;
      ctx.fillStyle = '#dfe4ea';
      ctx.font = '12px sans-serif';
      ctx.fillText(t.label.slice(0, 10), 4, y + 16);
      for (let f = 0; f < F; f++) {
        if (!t.values[f]) continue;
        ctx.fillStyle = t.values[f] > 0 ? '#3fa34d' : '#c0392b';
        ctx.fillRect(labelW + (f / F) * w, y + 3, Math.ceil(w / F) + 0.5, rowH - 6);
      }
      ctx.strokeStyle = '#343a43';
      ctx.strokeRect(labelW, y + 2, w, rowH - 4);
    });
    ctx.fillStyle = '#8a939e';
    ctx.font = '10px sans-serif';
    const fps = dbFps();
    for (let s = 0; s <= F / fps; s += Math.max(1, Math.round(F / fps / 6))) ctx.fillText(`${s}s`, labelW + ((s * fps) / F) * w, canvas.height - 3);
    if (!tl.tracks.length) ctx.fillText('add a label track to paint', labelW, 16);
    if (playhead !== null) {
      const x = labelW + Math.min((playhead * fps) / F, 1) * w;
      ctx.strokeStyle = '#f0a030';
      ctx.beginPath(); ctx.moveTo(x, 0); ctx.lineTo(x, canvas.height - 14); ctx.stroke();
    }
  };
  let playhead = null; // seconds, while a timeline result plays
  const dbFps = () => {
    const db = state.databases.find((d) => d.id === $('tl-db').value);
    return (db && db.fps) || 30;
  };
  const paintAt = (ev) => {
    const r = canvas.getBoundingClientRect();
    const x = ((ev.clientX - r.left) / r.width) * canvas.width - labelW;
    const y = ((ev.clientY - r.top) / r.height) * canvas.height;
    const row = Math.floor(y / rowH);
    const t = tl.tracks[painting.row ?? row];
    if (!t) return;
    painting.row = painting.row ?? row;
    const F = nFrames();
    const f = Math.floor((x / (canvas.width - labelW)) * F);
    const lo = Math.max(0, Math.min(f, painting.last ?? f));
    const hi = Math.min(F - 1, Math.max(f, painting.last ?? f));
    for (let i = lo; i <= hi; i++) t.values[i] = painting.value;
    painting.last = Math.max(0, Math.min(F - 1, f));
    redraw();
  };
  canvas.addEventListener('contextmenu', (ev) => ev.preventDefault());
  canvas.addEventListener('pointerdown', (ev) => {
    canvas.setPointerCapture(ev.pointerId);
    painting = { value: ev.altKey ? 0 : ev.button === 2 || ev.shiftKey ? -1 : 1 };
    paintAt(ev);
  });
  canvas.addEventListener('pointermove', (ev) => { if (painting) paintAt(ev); });
  canvas.addEventListener('pointerup', () => { painting = null; });
  const addTrack = (label) => {
    if (!label || tl.tracks.some((t) => t.label === label)) return;
    tl.tracks.push({ label, values: new Int8Array(nFrames()) });
    redraw();
  };
  $('tl-add').onclick = () =>
    guarded('timeline', async () => {
      const label = $('tl-new').value.trim();
      if (!label) throw new ApiError(0, 'invalid_input', 'name the label track to add (type it in the box beside Add)');
      if (tl.tracks.some((t) => t.label === label)) throw new ApiError(0, 'invalid_input', `there is a ${label} track already`);
      addTrack(label);
      $('tl-new').value = '';
    });
  $('tl-frames').oninput = redraw;
  $('tl-clear').onclick = () => { for (const t of tl.tracks) t.values.fill(0); redraw(); };
  // tracks: the chosen database's label vocabulary (its summary from the API, whoever built it);
  // painted values of labels it shares with the previous database are kept
  const refreshTracks = () => {
    const summary = summaryOf($('tl-db').value);
    if (!summary) return redraw();
    const old = new Map(tl.tracks.map((t) => [t.label, t]));
    tl.tracks = summary.labels.map((label) => old.get(label) || { label, values: new Int8Array(nFrames()) });
    const vocab = $('tl-vocab');
    vocab.textContent = '';
    for (const label of summary.labels) vocab.appendChild(new Option(label));
    // the correction loop names the database's own clips
    const sel = $('corr-clip');
    const keep = sel.value;
    sel.textContent = '';
    for (const c of summary.clips) sel.add(new Option(`${c.name} (${c.frames} frames)`, c.name));
    if (keep && summary.clips.some((c) => c.name === keep)) sel.value = keep;
    redraw();
  };
  $('tl-db').onchange = refreshTracks;
  // the timeline entries: runs of equal non-zero values per track
  const entries = () => {
    const out = [];
    for (const t of tl.tracks) {
      let start = 0;
      for (let f = 1; f <= t.values.length; f++) {
        if (f === t.values.length || t.values[f] !== t.values[start]) {
          if (t.values[start]) out.push({ label: t.label, start, end: f, value: t.values[start] });
          start = f;
        }
      }
    }
    return out;
  };
  tl.entries = entries;
  $('tl-go').onclick = () =>
    guarded('timeline', async () => {
      const db = dbOf('tl-db');
      const timelineEntries = entries();
      if (!timelineEntries.length) throw new ApiError(0, 'empty_timeline', 'paint at least one do / don\'t range');
      viewer.clear();
      await runJob('timeline', { engine: 'annotations', database: db, frames: nFrames(), budget_s: numberOf('tl-budget', 'budget', 0.1, 600), timeline: timelineEntries });
    });
  // the correction loop: set a label on a clip's frame range (POST /v1/databases/{id}/corrections:
  // the server writes the corrected spec and builds it; the SVMs retrain)
  $('corr-go').onclick = () =>
    guarded('correct', async () => {
      const id = dbOf('tl-db');
      const clip = $('corr-clip').value;
      const label = $('corr-label').value.trim();
      const start = Math.round(Number($('corr-start').value));
      const end = Math.round(Number($('corr-end').value));
      if (!clip) throw new ApiError(0, 'invalid_input', 'choose one of the database\'s clips');
      if (!label) throw new ApiError(0, 'invalid_input', 'name the label to correct');
      const correction = { clip, start, end, label, value: Number($('corr-value').value) };
      const info = await trackBuild('annotated', () => api.correct(id, [correction]));
      $('tl-db').value = info.id;
      refreshTracks();
    });
  const showTime = (t) => {
    const next = state.current && state.current.tool === 'timeline' ? t : null;
    if (next !== playhead && state.tool === 'timeline') {
      playhead = next;
      redraw();
    }
  };
  return { redraw, refreshTracks, addTrack, showTime };
})();

// -- Music: BPM or MIDI, steer with the mouse -> rhythmic synthesis; beat flashes
music = setupMusic({ state, $, api, runJob, guarded, dbOf, numberOf, viewer, ApiError, FloorPad, headingDeg, showError, framesText, characters });
tools.music = music;
// -- the rhythm database's movement graph (choreographic edits -> a derived database): graph.js
setupGraph({ state, $, guarded, clearError, refreshDatabases });

// ---------------------------------------------------------------- start
$('token').value = getToken();
$('token').onchange = () => { setToken($('token').value.trim()); boot(); };

async function boot() {
  try {
    state.health = await api.health();
    $('health').textContent = state.health.ok ? `service ok · ${state.health.backend?.backend || state.health.backend?.kind || 'backend'}` : 'service degraded';
  } catch {
    $('health').textContent = 'service unreachable';
  }
  await guarded('upload', loadSamples);
  await guarded('upload', refreshClips);
  await guarded('build', refreshDatabases);
  await guarded('build', loadDemos);
  state.ready = true;
}
boot();
setInterval(() => { if (state.ready) { refreshDatabases().catch(() => {}); characters.refresh().catch(() => {}); } }, 5000);
