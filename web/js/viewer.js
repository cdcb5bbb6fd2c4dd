// The viewer: each character ('leader', 'result', ...) as a skinned body (web/js/body.js) and/or a
// stick figure of its joints (the bones overlay; per-frame joint positions, metres, Y up), on a
// lit floor placed at the soles, with each character's trail on the floor, its foot contacts
// marked where the feet are planted, the request's goals drawn where they were asked (met or
// missed), and one clock for every character (play, pause, scrub, speed, frame steps) at its own
// fps; the camera follows the main character or stays.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';

export const COLORS = { result: 0xf0a030, leader: 0x4aa3ff, follower: 0xf0a030, clip: 0x7ccf7c };

const STATIC_M = 1e-3; // a joint moving less than this on the floor over a whole motion stays put

// The joint whose floor projection is the character's place: joint 0, unless joint 0 is a static
// ground node (Bandai-Namco's joint_Root, the world root of several dancers): then the first joint
// that moves (the hips). `named`: the hips by name, when the database summary gives them.
export function placeJoint(motion, named) {
  const { joints, parents, frames, positions } = motion;
  const J = parents.length;
  if (named && joints) {
    const j = joints.indexOf(named);
    if (j >= 0) return j;
  }
  const travel = (j) => {
    let lo = [Infinity, Infinity];
    let hi = [-Infinity, -Infinity];
    for (let f = 0; f < frames; f++) {
      const x = positions[(f * J + j) * 3];
      const z = positions[(f * J + j) * 3 + 2];
      lo = [Math.min(lo[0], x), Math.min(lo[1], z)];
      hi = [Math.max(hi[0], x), Math.max(hi[1], z)];
    }
    return Math.max(hi[0] - lo[0], hi[1] - lo[1]);
  };
  if (frames < 2 || travel(0) >= STATIC_M) return 0;
  for (let j = 1; j < J; j++) if (travel(j) >= STATIC_M) return j;
  return 0;
}

class Character {
  constructor(scene, motion, color, root) {
    this.motion = motion;
    const { parents, frames, positions } = motion;
    const J = parents.length;
    this.J = J;
    this.root = root === undefined ? placeJoint(motion) : root;
    const r = this.root;
    this.bones = [];
    parents.forEach((p, j) => { if (p >= 0) this.bones.push([p, j]); });
    this.group = new THREE.Group();
    const lineGeo = new THREE.BufferGeometry();
    lineGeo.setAttribute('position', new THREE.BufferAttribute(new Float32Array(this.bones.length * 6), 3));
    this.lines = new THREE.LineSegments(lineGeo, new THREE.LineBasicMaterial({ color }));
    const pointGeo = new THREE.BufferGeometry();
    pointGeo.setAttribute('position', new THREE.BufferAttribute(new Float32Array(J * 3), 3));
    this.points = new THREE.Points(pointGeo, new THREE.PointsMaterial({ color, size: 0.035 }));
    for (const o of [this.lines, this.points]) o.frustumCulled = false;
    // root trail: the place joint (the hips) projected on the floor, every frame
    const trail = new Float32Array(frames * 3);
    for (let f = 0; f < frames; f++) {
      trail[f * 3] = positions[(f * J + r) * 3];
      trail[f * 3 + 1] = 0.005;
      trail[f * 3 + 2] = positions[(f * J + r) * 3 + 2];
    }
    const trailGeo = new THREE.BufferGeometry();
    trailGeo.setAttribute('position', new THREE.BufferAttribute(trail, 3));
    this.trail = new THREE.Line(trailGeo, new THREE.LineBasicMaterial({ color, transparent: true, opacity: 0.55 }));
    this.marker = new THREE.Mesh(new THREE.RingGeometry(0.08, 0.12, 24), new THREE.MeshBasicMaterial({ color, side: THREE.DoubleSide }));
    this.marker.rotation.x = -Math.PI / 2;
    this.group.add(this.lines, this.points, this.trail, this.marker);
    scene.add(this.group);
    // where its soles are: the 10th percentile over frames of its lowest joint
    const lows = [];
    const step = Math.max(1, Math.ceil(frames / 300));
    for (let f = 0; f < frames; f += step) {
      let low = Infinity;
      for (let j = 0; j < J; j++) low = Math.min(low, positions[(f * J + j) * 3 + 1]);
      lows.push(low);
    }
    lows.sort((a, b) => a - b);
    this.floor = lows.length ? lows[Math.floor(lows.length * 0.1)] : 0;
    this.floorY = 0; // the viewer's floor (placeFloor)
  }

  get duration() {
    return Math.max(this.motion.frames - 1, 0) / this.motion.fps;
  }

  frameAt(t) {
    return Math.min(Math.max(Math.round(t * this.motion.fps), 0), this.motion.frames - 1);
  }

  show(t) {
    const f = this.frameAt(t);
    const { positions } = this.motion;
    const base = f * this.J * 3;
    const line = this.lines.geometry.attributes.position;
    this.bones.forEach(([p, j], i) => {
      for (let k = 0; k < 3; k++) {
        line.array[i * 6 + k] = positions[base + p * 3 + k];
        line.array[i * 6 + 3 + k] = positions[base + j * 3 + k];
      }
    });
    line.needsUpdate = true;
    const pts = this.points.geometry.attributes.position;
    pts.array.set(positions.subarray(base, base + this.J * 3));
    pts.needsUpdate = true;
    this.marker.position.set(positions[base + this.root * 3], this.floorY + 0.006, positions[base + this.root * 3 + 2]);
    return f;
  }

  bounds(box) {
    const { positions } = this.motion;
    for (let i = this.root * 3; i < positions.length; i += 3 * this.J) box.expandByPoint(new THREE.Vector3(positions[i], positions[i + 1], positions[i + 2]));
    return box;
  }

  dispose(scene) {
    scene.remove(this.group);
    this.group.traverse((o) => { if (o.geometry) o.geometry.dispose(); if (o.material) o.material.dispose(); });
  }
}


const CONTACT_COLORS = { left: 0x4aa3ff, right: 0xf06292, other: 0xdddddd };
const SHADOW_PATCH_M = 5; // the side of the floor patch that takes shadows, under the main character

// which side a joint is on, by its name (lFoot, LeftFoot, foot_l, mixamorig:LeftFoot...)
export function sideOf(name) {
  const n = String(name).replace(/^.*:/, '');
  if (/^l(?=[A-Z_])|^left|_l$|\.l$|_l_|left/i.test(n) && !/^right/i.test(n)) return 'left';
  if (/^r(?=[A-Z_])|^right|_r$|\.r$|_r_|right/i.test(n)) return 'right';
  return 'other';
}

export class Viewer {
  constructor(container) {
    this.container = container;
    this.renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio, 2));
    this.renderer.shadowMap.enabled = true;
    this.renderer.shadowMap.type = THREE.PCFShadowMap;
    container.appendChild(this.renderer.domElement);
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(0x1d2127);
    this.camera = new THREE.PerspectiveCamera(45, 1, 0.05, 500);
    this.camera.position.set(4, 3, 6);
    this.controls = new OrbitControls(this.camera, this.renderer.domElement);
    this.controls.target.set(0, 0.9, 0);
    // lights: a sky/ground fill and a key light from above and in front that casts the bodies'
    // shadows on the floor (what shows a foot on the floor, or not)
    this.scene.add(new THREE.HemisphereLight(0xe8eef6, 0x40444c, 1.6));
    this.key = new THREE.DirectionalLight(0xffffff, 2.2);
    this.key.position.set(3, 6, 4);
    this.key.castShadow = true;
    this.key.shadow.mapSize.set(1024, 1024);
    Object.assign(this.key.shadow.camera, { left: -4, right: 4, top: 4, bottom: -4, near: 0.5, far: 20 });
    this.scene.add(this.key, this.key.target);
    // the floor, at the soles' height: a flat plane and its grid, and where the main character
    // stands a patch that takes the bodies' shadows (shading the whole floor costs a software
    // renderer 3 times the frame time)
    this.floor = new THREE.Group();
    const plane = new THREE.Mesh(new THREE.PlaneGeometry(60, 60), new THREE.MeshBasicMaterial({ color: 0x262b32 }));
    plane.rotation.x = -Math.PI / 2;
    this.shadowPatch = new THREE.Mesh(new THREE.PlaneGeometry(SHADOW_PATCH_M, SHADOW_PATCH_M), new THREE.ShadowMaterial({ opacity: 0.4 }));
    this.shadowPatch.rotation.x = -Math.PI / 2;
    this.shadowPatch.position.y = 0.001;
    this.shadowPatch.receiveShadow = true;
    this.grid = new THREE.GridHelper(20, 20, 0x59606b, 0x3b424c);
    this.grid.position.y = 0.002;
    this.floor.add(plane, this.shadowPatch, this.grid, new THREE.AxesHelper(0.5));
    this.scene.add(this.floor);
    this.floorY = 0;
    this.marks = new THREE.Group(); // foot contacts and goals, on the floor
    this.floor.add(this.marks);
    this.characters = new Map();
    this.bodies = new Map();
    this.contacts = new Map(); // key -> [{mesh, start, end}]
    this.goals = null;
    this.showBodies = true;
    this.showBones = false;
    this.time = 0;
    this.speed = 1;
    this.playing = false;
    this.loop = true;
    this.follow = null; // the key the camera follows while a live session streams
    this.followMode = 'stay'; // 'follow': the camera follows the main character while it plays
    this.listeners = new Set();
    this.removedListeners = new Set(); // told the key of every character removed
    this.lastTick = performance.now();
    new ResizeObserver(() => this.resize()).observe(container);
    this.resize();
    this.renderer.setAnimationLoop(() => this.tick());
  }

  resize() {
    const w = this.container.clientWidth || 1;
    const h = this.container.clientHeight || 1;
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
  }

  get duration() {
    let d = 0;
    for (const c of this.characters.values()) d = Math.max(d, c.duration);
    for (const b of this.bodies.values()) d = Math.max(d, b.duration);
    return d;
  }

  // the main character: the result, else the first one
  get main() {
    if (this.characters.has('result') || this.bodies.has('result')) return 'result';
    return this.characters.keys().next().value || this.bodies.keys().next().value || null;
  }

  // the frame rate the transport steps by: the main character's
  get fps() {
    const key = this.main;
    const c = this.characters.get(key);
    return c ? c.motion.fps : this.bodies.get(key)?.fps || 30;
  }

  // `root`: the joint the ring and trail follow (default: placeJoint(motion))
  set(key, motion, color = COLORS[key] || 0xdddddd, { frame = true, root } = {}) {
    this.removeStick(key);
    this.characters.set(key, new Character(this.scene, motion, color, root));
    this.applyVisibility();
    this.placeFloor();
    if (frame) this.frameAll();
    this.seek(Math.min(this.time, this.duration));
    this.emit();
  }

  removeStick(key) {
    const c = this.characters.get(key);
    if (c) {
      c.dispose(this.scene);
      this.characters.delete(key);
    }
  }

  // a body for a character (a Body of body.js, posed already); `hips`: its hips joint's name
  setBody(key, body, hips) {
    if (this.bodies.get(key) !== body) this.removeBody(key, false);
    else this.dropTrail(body);
    body.hipsName = hips;
    this.scene.add(body.root);
    body.measure(hips, this.time);
    const trail = new THREE.BufferGeometry().setFromPoints(body.trail.map(([x, z]) => new THREE.Vector3(x, 0.005, z)));
    const color = this.characters.get(key)?.trail.material.color || new THREE.Color(COLORS[key] || 0xdddddd);
    body.trailLine = new THREE.Line(trail, new THREE.LineBasicMaterial({ color, transparent: true, opacity: 0.55 }));
    this.marks.add(body.trailLine);
    this.bodies.set(key, body);
    this.setContacts(key, body);
    this.placeFloor();
    this.applyVisibility();
    this.seek(Math.min(this.time, this.duration));
    this.emit();
  }

  dropTrail(body) {
    if (!body.trailLine) return;
    this.marks.remove(body.trailLine);
    body.trailLine.geometry.dispose();
    body.trailLine.material.dispose();
    body.trailLine = null;
  }

  removeBody(key, notify = true) {
    const b = this.bodies.get(key);
    if (b) {
      this.dropTrail(b);
      b.dispose();
      this.bodies.delete(key);
    }
    this.clearContacts(key);
    if (notify) { this.placeFloor(); this.applyVisibility(); this.emit(); }
  }

  remove(key, notify = true) {
    this.removeStick(key);
    this.removeBody(key, false);
    for (const fn of this.removedListeners) fn(key);
    if (notify) { this.placeFloor(); this.emit(); }
  }

  clear() {
    for (const key of new Set([...this.characters.keys(), ...this.bodies.keys()])) this.remove(key, false);
    this.setGoals(null);
    this.placeFloor();
    this.emit();
  }

  has(key) {
    return this.characters.has(key) || this.bodies.has(key);
  }

  setTrails(visible) {
    this.trails = visible;
    this.applyVisibility();
  }

  // the bodies (skinned meshes) and the bones overlay (stick figures): a character without a body
  // is always its stick figure; with one, the stick figure shows when the bones overlay is on, or
  // when bodies are hidden
  setDisplay({ bodies = this.showBodies, bones = this.showBones } = {}) {
    this.showBodies = bodies;
    this.showBones = bones;
    this.applyVisibility();
    this.placeFloor();
    this.emit();
  }

  applyVisibility() {
    for (const [key, c] of this.characters) {
      const body = this.bodies.get(key);
      const stick = !this.hidden && (!body || !this.showBodies || this.showBones);
      c.lines.visible = stick;
      c.points.visible = stick;
      // over a body, the bones draw through it
      for (const o of [c.lines, c.points]) { o.material.depthTest = !body || !this.showBodies; o.renderOrder = body ? 2 : 0; }
      c.trail.visible = this.trails !== false && !(body && this.showBodies);
      c.marker.visible = !(body && this.showBodies);
    }
    for (const [key, b] of this.bodies) {
      b.root.visible = this.showBodies && !this.hidden;
      if (b.trailLine) b.trailLine.visible = this.showBodies && this.trails !== false;
      for (const m of this.contacts.get(key) || []) m.mesh.visible = true;
    }
  }

  // The viewer's pixels now (RGBA, row by row) as drawn with the characters shown as `display`
  // ({bodies, bones}, or hidden: the floor and its marks alone); the display is restored after.
  capture(display) {
    const keep = { bodies: this.showBodies, bones: this.showBones, hidden: this.hidden };
    if (display === 'hidden') this.hidden = true;
    else Object.assign(this, { showBodies: display.bodies, showBones: display.bones });
    this.applyVisibility();
    this.draw();
    this.renderer.render(this.scene, this.camera);
    const canvas = this.renderer.domElement;
    const copy = document.createElement('canvas');
    copy.width = canvas.width;
    copy.height = canvas.height;
    const ctx = copy.getContext('2d');
    ctx.drawImage(canvas, 0, 0);
    const pixels = ctx.getImageData(0, 0, copy.width, copy.height).data;
    Object.assign(this, { showBodies: keep.bodies, showBones: keep.bones, hidden: keep.hidden });
    this.applyVisibility();
    return pixels;
  }

  // the floor at the soles: the lowest of the shown characters' soles (a body's measured on its
  // mesh, a stick figure's at its lowest joints); 0 without characters
  placeFloor() {
    const floors = [];
    for (const [key, b] of this.bodies) if (this.showBodies && b.floor !== undefined && Number.isFinite(b.floor)) floors.push(b.floor);
    for (const [key, c] of this.characters) if (!(this.bodies.has(key) && this.showBodies)) floors.push(c.floor);
    this.floorY = floors.length ? Math.min(...floors) : 0;
    this.floor.position.y = this.floorY;
    for (const c of this.characters.values()) { c.floorY = this.floorY; c.trail.position.y = this.floorY; }
  }

  // foot contacts of a body (the service's contact events: joint, time_s, duration_s), each a
  // footprint on the floor where that foot stands at the plant's middle, lit while it is planted
  setContacts(key, body) {
    this.clearContacts(key);
    const marks = [];
    const t = this.time;
    for (const e of body.events.filter((ev) => ev.type === 'contact')) {
      const p = body.jointAt(e.joint, e.time_s + (e.duration_s || 0) / 2);
      if (!p) continue;
      const color = CONTACT_COLORS[sideOf(e.joint)];
      const mesh = new THREE.Mesh(new THREE.CircleGeometry(0.07, 20), new THREE.MeshBasicMaterial({ color, transparent: true, opacity: 0.35, depthWrite: false }));
      mesh.rotation.x = -Math.PI / 2;
      mesh.position.set(p.x, 0.004, p.z);
      this.marks.add(mesh);
      marks.push({ mesh, start: e.time_s, end: e.time_s + (e.duration_s || 0), joint: e.joint });
    }
    body.pose(t);
    this.contacts.set(key, marks);
  }

  clearContacts(key) {
    for (const m of this.contacts.get(key) || []) { this.marks.remove(m.mesh); m.mesh.geometry.dispose(); m.mesh.material.dispose(); }
    this.contacts.delete(key);
  }

  // goals drawn where they were asked: [{position: [x, z], heading_deg?, met, label, reached?: [x, z]}];
  // met in green, missed in red with a line to where the body was at that moment
  setGoals(goals) {
    if (this.goals) {
      this.marks.remove(this.goals);
      this.goals.traverse((o) => { if (o.geometry) o.geometry.dispose(); if (o.material) o.material.dispose(); });
      this.goals = null;
    }
    if (!goals || !goals.length) return;
    this.goals = new THREE.Group();
    for (const g of goals) {
      const color = g.met === false ? 0xff5252 : g.met === true ? 0x66d17a : 0xb0b8c2;
      const ring = new THREE.Mesh(new THREE.RingGeometry(0.16, 0.22, 32), new THREE.MeshBasicMaterial({ color, side: THREE.DoubleSide, depthWrite: false }));
      ring.rotation.x = -Math.PI / 2;
      ring.position.set(g.position[0], 0.006, g.position[1]);
      this.goals.add(ring);
      if (g.heading_deg !== undefined && g.heading_deg !== null) {
        const a = (g.heading_deg * Math.PI) / 180;
        const arrow = new THREE.ArrowHelper(new THREE.Vector3(Math.sin(a), 0, Math.cos(a)), new THREE.Vector3(g.position[0], 0.01, g.position[1]), 0.5, color, 0.14, 0.09);
        this.goals.add(arrow);
      }
      if (g.reached && g.met === false) {
        const geo = new THREE.BufferGeometry().setFromPoints([new THREE.Vector3(g.position[0], 0.01, g.position[1]), new THREE.Vector3(g.reached[0], 0.01, g.reached[1])]);
        this.goals.add(new THREE.Line(geo, new THREE.LineDashedMaterial({ color, dashSize: 0.06, gapSize: 0.04 })).computeLineDistances());
      }
    }
    this.marks.add(this.goals);
  }

  // every character's floor extent (and its height) in view
  frameAll() {
    const box = new THREE.Box3();
    for (const c of this.characters.values()) c.bounds(box);
    for (const b of this.bodies.values()) if (b.box) box.union(b.box);
    if (box.isEmpty()) return;
    const center = box.getCenter(new THREE.Vector3());
    const size = box.getSize(new THREE.Vector3());
    // far enough for the floor extent of every trail (plus a body) to fit the narrower field of view
    const half = Math.max(size.x, size.z, 1.5) / 2 + 0.6;
    const tanHalf = Math.tan((this.camera.fov * Math.PI) / 360);
    const dist = (half / tanHalf / Math.min(this.camera.aspect, 1)) * 1.05 + 0.5;
    const dir = new THREE.Vector3(0.45, 0.5, 0.74).normalize();
    const y = this.floorY + 0.9;
    this.controls.target.set(center.x, y, center.z);
    this.camera.position.set(center.x + dir.x * dist, y + dir.y * dist, center.z + dir.z * dist);
    this.controls.update();
  }

  // where a character is now: its body's hips, else its stick figure's place joint
  placeOf(key) {
    const b = this.bodies.get(key);
    if (b && this.showBodies) return b.hipsNow(b.hipsName);
    const c = this.characters.get(key);
    if (!c) return null;
    const base = (c.frameAt(this.time) * c.J + c.root) * 3;
    return new THREE.Vector3(c.motion.positions[base], c.motion.positions[base + 1], c.motion.positions[base + 2]);
  }

  // keep a character in view: glide the orbit target (and the camera with it) towards it
  followCharacter(key, rate = 0.08) {
    const p = key && this.placeOf(key);
    if (!p) return;
    const dx = (p.x - this.controls.target.x) * rate;
    const dz = (p.z - this.controls.target.z) * rate;
    this.controls.target.x += dx;
    this.controls.target.z += dz;
    this.camera.position.x += dx;
    this.camera.position.z += dz;
  }

  // the key light, its shadow and the patch that takes it go with the main character
  placeShadow() {
    const p = this.main && this.placeOf(this.main);
    if (!p) return;
    this.key.target.position.set(p.x, this.floorY, p.z);
    this.key.position.set(p.x + 3, this.floorY + 6, p.z + 4);
    this.shadowPatch.position.x = p.x;
    this.shadowPatch.position.z = p.z;
  }

  setFollow(mode) {
    this.followMode = mode === 'follow' ? 'follow' : 'stay';
    if (this.followMode === 'stay') this.frameAll();
    this.emit();
  }

  play() { this.playing = true; this.lastTick = performance.now(); this.emit(); }
  pause() { this.playing = false; this.emit(); }
  seek(t) {
    this.time = Math.min(Math.max(t, 0), this.duration);
    this.draw();
    this.emit();
  }

  // one frame forward or back (at the main character's rate), paused
  step(frames) {
    this.pause();
    const fps = this.fps;
    const f = Math.round(this.time * fps) + frames;
    this.seek(Math.min(Math.max(f, 0), Math.round(this.duration * fps)) / fps);
  }

  onChange(fn) { this.listeners.add(fn); }
  onRemove(fn) { this.removedListeners.add(fn); }
  emit() { for (const fn of this.listeners) fn(this); }

  draw() {
    this.frames = {};
    for (const [key, c] of this.characters) this.frames[key] = c.show(this.time);
    for (const [key, b] of this.bodies) {
      b.pose(this.time);
      if (!this.characters.has(key)) this.frames[key] = b.frameAt(this.time);
      for (const m of this.contacts.get(key) || []) {
        const on = this.time >= m.start && this.time <= m.end;
        m.mesh.material.opacity = on ? 0.95 : 0.35;
        m.mesh.scale.setScalar(on ? 1.25 : 1);
      }
    }
  }

  tick() {
    const now = performance.now();
    const dt = (now - this.lastTick) / 1000;
    this.lastTick = now;
    if (this.playing && (this.characters.size || this.bodies.size)) {
      const d = this.duration;
      this.time += dt * this.speed;
      if (this.time > d) this.time = this.loop && d > 0 ? this.time % d : d;
      this.draw();
      this.emit();
    }
    if (this.follow) this.followCharacter(this.follow);
    else if (this.followMode === 'follow') this.followCharacter(this.main, 0.12);
    this.placeShadow();
    this.controls.update();
    this.renderer.render(this.scene, this.camera);
  }
}
