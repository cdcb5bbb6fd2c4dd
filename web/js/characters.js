// The `character` picker and the bodies it puts in the viewer.
//
// The picker offers the uploaded glTF/GLB files (characters: a skinned mesh with its materials)
// and BVH clips (a skeleton, worn by Segue's mannequin), beside "Segue's mannequin" (the default:
// the motion's own skeleton wearing the mannequin). Whatever the viewer shows is drawn on it:
// * a result: the result downloaded as GLB on the character (GET /v1/jobs/{id}/result?format=glb
//   &character=...&events=contacts, with mesh=body for the mannequin): the retargeting every
//   download uses, done by the service, with the foot contacts it measured on the body's feet;
// * a clip or a live session's frames: the character's model (POST /v1/characters/model) moved
//   frame by frame by its binding to the motion's skeleton (POST /v1/characters/binding: the
//   retargeting's own transfer, measured by the service once; web/js/body.js applies it).
// The picker also chooses the character of the downloads (as before: ""= as computed).
import { ApiError, request } from './api.js';
import { Body, examplePayload, loadGltf, skeletonPayload } from './body.js';

const GLTF = /\.(glb|gltf)$/i;
const LIVE_EXAMPLE_FRAMES = 90; // a live session's binding is measured again on its first 3 s

export function isCharacterFile(f) {
  return GLTF.test(f.name) || /^model\/gltf/.test(f.media_type || '');
}

export function setupCharacters({ state, $, api, viewer, guarded, clearError, showError, clipName }) {
  const c = { files: [], shown: {}, loading: {}, errors: [], live: {} };
  state.characters = c;
  const models = new Map(); // character key -> model bytes (ArrayBuffer)
  const bindings = new Map(); // character + skeleton (+ example) -> binding JSON
  const tokens = {}; // viewer key -> the newest request's token (older answers are dropped)
  const sources = new Map(); // viewer key -> what it shows: {kind, motion, hips, job, result, live}

  const picked = () => $('character').value;
  const pickedKind = () => {
    const v = picked();
    if (!v) return 'mannequin';
    return c.files.some((f) => f.id === v) ? 'file' : 'clip';
  };
  const label = () => {
    const opt = $('character').selectedOptions[0];
    return opt ? opt.textContent : 'mannequin';
  };

  // the picker: Segue's mannequin, then the uploaded glTF/GLB files, then the BVH clips (files any
  // client uploads are offered at the page's next refresh); left alone while nothing changed
  let signature = '';
  const refresh = async () => {
    const files = await api.files();
    c.files = files.filter(isCharacterFile);
    const now = JSON.stringify([c.files.map((f) => [f.id, f.name]), state.clips.map((x) => [x.id, x.name])]);
    if (now === signature) return;
    signature = now;
    const sel = $('character');
    const keep = sel.value;
    sel.textContent = '';
    sel.add(new Option("Segue's mannequin", ''));
    for (const f of c.files) sel.add(new Option(`${f.name} (glTF)`, f.id));
    for (const clip of state.clips) sel.add(new Option(`${clip.name} (BVH skeleton)`, clip.id));
    if ([...sel.options].some((o) => o.value === keep)) sel.value = keep;
    c.options = [...sel.options].map((o) => ({ value: o.value, label: o.textContent }));
  };

  $('character-file').onchange = (ev) =>
    guarded('character', async () => {
      for (const file of ev.target.files) {
        if (!GLTF.test(file.name)) throw new ApiError(0, 'not_a_character', `${file.name}: a character is a .glb or .gltf file (a skinned mesh)`);
        const info = await api.uploadFile(file.name, await file.arrayBuffer());
        await refresh();
        $('character').value = info.id;
      }
      ev.target.value = '';
      await reshow();
    });
  $('character').addEventListener('change', () => guarded('character', reshow));
  $('feet').addEventListener('change', () => guarded('character', reshow)); // the body wears the downloads' feet

  const modelKey = (kind, id, skeleton) => (kind === 'file' ? `file:${id}` : `${kind}:${id}:${skeleton.names.join(',')}`);
  const model = async (kind, id, skeleton) => {
    const key = modelKey(kind, id, skeleton);
    if (!models.has(key)) {
      const bytes = await (await request('POST', '/v1/characters/model', { json: { character: id || null, skeleton } })).arrayBuffer();
      models.set(key, bytes);
    }
    return models.get(key);
  };
  const binding = async (id, skeleton, example, name) => {
    const key = `${id}|${skeleton.names.join(',')}|${example ? name : ''}`;
    if (!bindings.has(key)) {
      const json = { character: id || null, skeleton };
      if (example) json.example = example;
      bindings.set(key, (await request('POST', '/v1/characters/binding', { json })).json());
    }
    return bindings.get(key);
  };

  // Show what the viewer key draws on the picked character. `what`: {kind: 'result', job,
  // result, motion, hips} or {kind: 'motion', motion, hips, live}; motion: the parsed motion
  // drawn as the stick figure (its skeleton is what the body binds to).
  const show = async (key, what) => {
    sources.set(key, what);
    const t0 = performance.now();
    const token = (tokens[key] = (tokens[key] || 0) + 1);
    const kind = pickedKind();
    const id = picked();
    c.loading[key] = true;
    clearError('character');
    try {
      let body;
      const skeleton = skeletonPayload(what.motion);
      if (what.kind === 'result') {
        // the download itself: the result retargeted by the service onto the character (or worn
        // by the mannequin), with the foot contacts measured on it
        const hips = kind === 'mannequin' ? what.hips : (await binding(id, skeleton, null, '')).hips.joint;
        const blob = await api.resultBlob(what.job, what.result, 'glb', 30, id, 'contacts', kind === 'file' ? undefined : 'body', $('feet').value);
        if (tokens[key] !== token) return null;
        body = new Body(await loadGltf(await blob.arrayBuffer()), label());
        body.hipsJoint = hips;
      } else {
        const example = what.live ? null : examplePayload(what.motion);
        const b = await binding(id, skeleton, example, what.motion.name);
        const bytes = await model(kind, id, skeleton);
        if (tokens[key] !== token) return null;
        body = new Body(await loadGltf(bytes.slice(0)), label());
        body.bind(b, what.motion);
        body.hipsJoint = b.hips.joint;
        c.bindings = { ...c.bindings, [key]: b };
      }
      if (tokens[key] !== token) { body.dispose(); return null; }
      viewer.setBody(key, body, body.hipsJoint);
      // ms: from asking for the body to its drawing (the service's export or binding, the download,
      // three.js's parse, measuring the soles)
      c.shown[key] = { ...body.info(), character: id || 'mannequin', kind, what: what.kind, live: Boolean(what.live), floor: body.floor, ms: performance.now() - t0 };
      c.errors = [];
      return body;
    } catch (exc) {
      if (tokens[key] === token) {
        viewer.removeBody(key);
        delete c.shown[key];
        c.errors.push({ key, message: exc.message });
        showError('character', exc);
      }
      return null;
    } finally {
      if (tokens[key] === token) c.loading[key] = false;
    }
  };

  // a live session's motion grew: the body follows; once there are enough frames, its binding is
  // measured again on them (the floor, the hip height, how a foot lies planted)
  const live = async (key, motion) => {
    const body = viewer.bodies.get(key);
    const now = sources.get(key);
    if (!now || !now.live || (!body && !c.loading[key])) {
      c.live[key] = { refined: false };
      return show(key, { kind: 'motion', motion, hips: null, live: true });
    }
    if (now) now.motion = motion;
    const l = c.live[key] || (c.live[key] = { refined: false, measured: 0 });
    if (body) {
      body.extend(motion);
      if (c.shown[key]) Object.assign(c.shown[key], { duration: body.duration, frames: motion.frames });
      // the trail and the floor follow the session (measured again every second of frames)
      if (motion.frames - (l.measured || 0) >= motion.fps) {
        l.measured = motion.frames;
        viewer.setBody(key, body, body.hipsJoint);
      }
    }
    if (!l.refined && motion.frames >= LIVE_EXAMPLE_FRAMES && body && pickedKind() !== 'mannequin') {
      l.refined = true;
      const example = examplePayload(motion, LIVE_EXAMPLE_FRAMES);
      try {
        const b = await binding(picked(), skeletonPayload(motion), example, `${motion.name}#${motion.frames}`);
        if (viewer.bodies.get(key) === body) { body.bind(b, now.motion); viewer.setBody(key, body, b.hips.joint); }
      } catch (exc) {
        showError('character', exc);
      }
    }
    return body;
  };

  // test hook: where the body's joints are at time t (world, metres), by joint name
  c.joints = (key, t, names) => {
    const body = viewer.bodies.get(key);
    if (!body) return null;
    const out = {};
    for (const n of names) { const p = body.jointAt(n, t); out[n] = p ? [p.x, p.y, p.z] : null; }
    body.pose(viewer.time);
    return out;
  };

  const forget = (key) => {
    sources.delete(key);
    tokens[key] = (tokens[key] || 0) + 1;
    delete c.shown[key];
  };

  viewer.onRemove(forget); // a character the viewer no longer draws is not shown again

  const reshow = async () => {
    await Promise.all([...sources].map(([key, what]) => show(key, what)));
  };

  return { refresh, show, live, forget, reshow, picked };
}
