// The skeleton viewer: stick figures from per-frame joint positions (metres, Y up), a ground grid,
// each character's root trail on the floor, and one clock for every character (play, pause,
// scrub, speed). Characters are keyed ('leader', 'result', ...) and play at their own fps.
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
    this.marker.position.set(positions[base + this.root * 3], 0.006, positions[base + this.root * 3 + 2]);
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

export class Viewer {
  constructor(container) {
    this.container = container;
    this.renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio, 2));
    container.appendChild(this.renderer.domElement);
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(0x1d2127);
    this.camera = new THREE.PerspectiveCamera(45, 1, 0.05, 500);
    this.camera.position.set(4, 3, 6);
    this.controls = new OrbitControls(this.camera, this.renderer.domElement);
    this.controls.target.set(0, 0.9, 0);
    this.grid = new THREE.GridHelper(20, 20, 0x59606b, 0x353b44);
    this.scene.add(this.grid);
    this.scene.add(new THREE.AxesHelper(0.5));
    this.characters = new Map();
    this.time = 0;
    this.speed = 1;
    this.playing = false;
    this.loop = true;
    this.listeners = new Set();
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
    return d;
  }

  // `root`: the joint the ring and trail follow (default: placeJoint(motion))
  set(key, motion, color = COLORS[key] || 0xdddddd, { frame = true, root } = {}) {
    this.remove(key, false);
    this.characters.set(key, new Character(this.scene, motion, color, root));
    if (frame) this.frameAll();
    this.seek(Math.min(this.time, this.duration));
    this.emit();
  }

  remove(key, notify = true) {
    const c = this.characters.get(key);
    if (c) {
      c.dispose(this.scene);
      this.characters.delete(key);
      if (notify) this.emit();
    }
  }

  clear() {
    for (const key of [...this.characters.keys()]) this.remove(key, false);
    this.emit();
  }

  has(key) {
    return this.characters.has(key);
  }

  setTrails(visible) {
    for (const c of this.characters.values()) c.trail.visible = visible;
    this.trails = visible;
  }

  frameAll() {
    const box = new THREE.Box3();
    for (const c of this.characters.values()) c.bounds(box);
    if (box.isEmpty()) return;
    const center = box.getCenter(new THREE.Vector3());
    const size = box.getSize(new THREE.Vector3());
    // far enough for the floor extent of every trail (plus a body) to fit the narrower field of view
    const half = Math.max(size.x, size.z, 1.5) / 2 + 0.6;
    const tanHalf = Math.tan((this.camera.fov * Math.PI) / 360);
    const dist = (half / tanHalf / Math.min(this.camera.aspect, 1)) * 1.05 + 0.5;
    const dir = new THREE.Vector3(0.45, 0.5, 0.74).normalize();
    this.controls.target.set(center.x, 0.9, center.z);
    this.camera.position.set(center.x + dir.x * dist, 0.9 + dir.y * dist, center.z + dir.z * dist);
    this.controls.update();
  }

  // keep a character in view: glide the orbit target (and the camera with it) towards its root
  followCharacter(c) {
    if (!c) return;
    const base = (c.frameAt(this.time) * c.J + c.root) * 3;
    const dx = (c.motion.positions[base] - this.controls.target.x) * 0.08;
    const dz = (c.motion.positions[base + 2] - this.controls.target.z) * 0.08;
    this.controls.target.x += dx;
    this.controls.target.z += dz;
    this.camera.position.x += dx;
    this.camera.position.z += dz;
  }

  play() { this.playing = true; this.lastTick = performance.now(); this.emit(); }
  pause() { this.playing = false; this.emit(); }
  seek(t) {
    this.time = Math.min(Math.max(t, 0), this.duration);
    this.draw();
    this.emit();
  }

  onChange(fn) { this.listeners.add(fn); }
  emit() { for (const fn of this.listeners) fn(this); }

  draw() {
    this.frames = {};
    for (const [key, c] of this.characters) {
      c.trail.visible = this.trails !== false;
      this.frames[key] = c.show(this.time);
    }
  }

  tick() {
    const now = performance.now();
    const dt = (now - this.lastTick) / 1000;
    this.lastTick = now;
    if (this.playing && this.characters.size) {
      const d = this.duration;
      this.time += dt * this.speed;
      if (this.time > d) this.time = this.loop && d > 0 ? this.time % d : d;
      this.draw();
      this.emit();
    }
    if (this.follow) this.followCharacter(this.characters.get(this.follow));
    this.controls.update();
    this.renderer.render(this.scene, this.camera);
  }
}
