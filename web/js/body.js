// Bodies: skinned characters in the viewer (three.js SkinnedMesh with the file's own materials).
//
// A body plays in one of two ways:
// * its own animation: a result the service retargeted onto the character (GET
//   /v1/jobs/{id}/result?format=glb&character=...: the download itself, foot planting included),
//   with the foot contacts the service measured on it (the animation's extras.events);
// * frame by frame, by a binding (POST /v1/characters/binding: the retargeting's own transfer,
//   measured once by the service for the character and the source skeleton) applied to motion
//   the page holds: a clip it plays, a live session's frames as they arrive. Per frame and joint:
//   world rotation = source world rotation x offset; joints the binding leaves out keep their
//   rest rotation; the hips go where the source's hips go, scaled (motion/retarget/binding.py
//   applies the same binding in Python).
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';

const SAMPLES = 60; // frames sampled to measure a body's sole, trail and bounds
const LOW_BAND_M = 0.15; // vertices this close above the bind pose's lowest point are the soles

// the skin's joint name of a bone: glTF names as written (GLTFLoader sanitizes bone.name)
const jointName = (bone) => (bone.userData && bone.userData.name) || bone.name;

export async function loadGltf(bytes) {
  return new GLTFLoader().parseAsync(bytes, '');
}

export class Body {
  // gltf: GLTFLoader's result; label: what the page calls the character
  constructor(gltf, label) {
    this.label = label;
    this.root = gltf.scene;
    this.skinned = [];
    this.root.traverse((o) => {
      if (o.isSkinnedMesh) {
        this.skinned.push(o);
        o.frustumCulled = false; // its bounds are the bind pose's: a walk leaves them
        o.castShadow = true;
      }
    });
    if (!this.skinned.length) throw new Error(`${label} holds no skinned mesh: it cannot be drawn as a body`);
    this.bones = this.skinned[0].skeleton.bones;
    this.byName = new Map(this.bones.map((b) => [jointName(b), b]));
    this.clip = gltf.animations.length ? gltf.animations[gltf.animations.length - 1] : null;
    this.events = (this.clip && this.clip.userData && this.clip.userData.events) || [];
    this.mixer = null;
    this.drive = null;
    this.duration = 0;
    this.fps = 30;
    if (this.clip) {
      this.mixer = new THREE.AnimationMixer(this.root);
      this.mixer.clipAction(this.clip).play();
      this.duration = this.clip.duration;
      const times = this.clip.tracks.find((t) => t.times.length > 1);
      if (times) this.fps = (times.times.length - 1) / (times.times[times.times.length - 1] - times.times[0]);
    }
    this.root.updateMatrixWorld(true);
    this.rest = new Map(this.bones.map((b) => [b, { q: b.quaternion.clone(), p: b.position.clone() }]));
    this.lowVertices = this.findLowVertices();
  }

  // what the page's state reports about the body (tests read it)
  info() {
    let vertices = 0;
    const materials = new Set();
    for (const m of this.skinned) {
      vertices += m.geometry.attributes.position.count;
      for (const mat of [].concat(m.material)) materials.add(mat.name || mat.type);
    }
    return { label: this.label, meshes: this.skinned.length, vertices, bones: this.bones.length, materials: [...materials],
      mode: this.mixer ? 'animation' : 'binding', duration: this.duration, contacts: this.events.filter((e) => e.type === 'contact').length };
  }

  // Drive the body frame by frame from `source` (a parsed motion: joints, parents, frames, fps,
  // positions F*J*3 and global rotations F*J*4) by `binding` (the service's JSON).
  bind(binding, source) {
    const index = new Map(source.joints.map((n, j) => [n, j]));
    const missing = binding.joints.filter((j) => !this.byName.has(j.joint) || !index.has(j.source)).map((j) => j.joint);
    if (missing.length) throw new Error(`the binding names joints ${this.label} or the motion lacks: ${missing.slice(0, 4).join(', ')}`);
    const driven = new Map(binding.joints.map((j) => [this.byName.get(j.joint), { src: index.get(j.source), offset: new THREE.Quaternion(...j.offset) }]));
    // every bone of the skin, parents first, with what drives it
    const order = [];
    const visit = (o) => {
      if (o.isBone && this.rest.has(o)) order.push(o);
      for (const c of o.children) visit(c);
    };
    visit(this.root);
    const h = binding.hips;
    this.drive = { source, order, driven, hips: { bone: this.byName.get(h.joint), src: index.get(h.source), scale: h.scale, sf: h.source_floor, tf: h.target_floor } };
    this.duration = source.frames > 1 ? (source.frames - 1) / source.fps : 0;
    this.fps = source.fps;
  }

  // the source grew (a live session's frames): same skeleton, more frames
  extend(source) {
    if (!this.drive) return;
    this.drive.source = source;
    this.duration = source.frames > 1 ? (source.frames - 1) / source.fps : 0;
  }

  frameAt(t) {
    const frames = this.drive ? this.drive.source.frames : Math.round(this.duration * this.fps) + 1;
    return Math.min(Math.max(Math.round(t * this.fps), 0), Math.max(frames - 1, 0));
  }

  // pose the body at time t (seconds)
  pose(t) {
    if (this.mixer) {
      this.mixer.setTime(Math.min(Math.max(t, 0), this.duration));
      this.root.updateMatrixWorld(true);
    } else if (this.drive) {
      this.applyFrame(this.frameAt(t));
    }
  }

  applyFrame(f) {
    const { source, order, driven, hips } = this.drive;
    const J = source.joints.length;
    const world = new Map();
    const parentWorld = new THREE.Quaternion();
    const q = new THREE.Quaternion();
    for (const bone of order) {
      const p = bone.parent;
      if (world.has(p)) parentWorld.copy(world.get(p));
      else p.getWorldQuaternion(parentWorld);
      const d = driven.get(bone);
      const w = new THREE.Quaternion();
      if (d) {
        const o = (f * J + d.src) * 4;
        q.set(source.rotations[o], source.rotations[o + 1], source.rotations[o + 2], source.rotations[o + 3]);
        w.multiplyQuaternions(q, d.offset);
        bone.quaternion.copy(parentWorld).invert().multiply(w);
      } else {
        const rest = this.rest.get(bone);
        bone.quaternion.copy(rest.q);
        w.multiplyQuaternions(parentWorld, rest.q);
      }
      world.set(bone, w);
    }
    this.root.updateMatrixWorld(true);
    if (hips.bone && hips.src !== undefined) {
      const o = (f * J + hips.src) * 3;
      const pos = source.positions;
      const target = new THREE.Vector3(hips.scale * pos[o], hips.tf + hips.scale * (pos[o + 1] - hips.sf), hips.scale * pos[o + 2]);
      hips.bone.position.copy(hips.bone.parent.worldToLocal(target));
      hips.bone.updateMatrixWorld(true);
    }
  }

  // vertices near the bind pose's lowest point, per skinned mesh (where the soles are)
  findLowVertices() {
    const out = [];
    const v = new THREE.Vector3();
    let lowest = Infinity;
    for (const m of this.skinned) {
      const n = m.geometry.attributes.position.count;
      for (let i = 0; i < n; i++) {
        m.getVertexPosition(i, v);
        v.applyMatrix4(m.matrixWorld);
        lowest = Math.min(lowest, v.y);
      }
    }
    for (const m of this.skinned) {
      const n = m.geometry.attributes.position.count;
      const idx = [];
      for (let i = 0; i < n; i++) {
        m.getVertexPosition(i, v);
        v.applyMatrix4(m.matrixWorld);
        if (v.y < lowest + LOW_BAND_M) idx.push(i);
      }
      out.push({ mesh: m, idx: idx.length > 300 ? idx.filter((_, k) => k % Math.ceil(idx.length / 300) === 0) : idx });
    }
    return out;
  }

  // the lowest sole point of the current pose (world y, metres)
  soleNow() {
    const v = new THREE.Vector3();
    let low = Infinity;
    for (const { mesh, idx } of this.lowVertices) {
      for (const i of idx) {
        mesh.getVertexPosition(i, v);
        v.applyMatrix4(mesh.matrixWorld);
        if (v.y < low) low = v.y;
      }
    }
    return low;
  }

  // Sample the motion: the floor under the soles (the 10th percentile over frames of the lowest
  // sole point: where the feet stand), the hips' floor trail and the bounds. Leaves the body at t.
  measure(hipsName, t = 0) {
    const frames = this.frameAt(this.duration) + 1;
    const step = Math.max(1, Math.ceil(frames / SAMPLES));
    const soles = [];
    const box = new THREE.Box3();
    const hips = (hipsName && this.byName.get(hipsName)) || this.bones[0];
    const trail = [];
    const p = new THREE.Vector3();
    for (let f = 0; f < frames; f += step) {
      this.pose(f / this.fps);
      soles.push(this.soleNow());
      hips.getWorldPosition(p);
      trail.push([p.x, p.z]);
      box.expandByPoint(p);
    }
    soles.sort((a, b) => a - b);
    this.floor = soles.length ? soles[Math.floor(soles.length * 0.1)] : 0;
    this.trail = trail;
    this.box = box;
    this.pose(t);
    return this.floor;
  }

  // where a joint is at time t (world), e.g. a foot at a contact's middle
  jointAt(name, t) {
    const bone = this.byName.get(name);
    if (!bone) return null;
    this.pose(t);
    return bone.getWorldPosition(new THREE.Vector3());
  }

  hipsNow(hipsName) {
    const hips = (hipsName && this.byName.get(hipsName)) || this.bones[0];
    return hips.getWorldPosition(new THREE.Vector3());
  }

  dispose() {
    if (this.mixer) this.mixer.stopAllAction();
    this.root.traverse((o) => {
      if (o.geometry) o.geometry.dispose();
      for (const m of [].concat(o.material || [])) {
        for (const value of Object.values(m)) if (value && value.isTexture) value.dispose();
        m.dispose();
      }
    });
    if (this.root.parent) this.root.parent.remove(this.root);
  }
}

// The source motion's skeleton as POST /v1/characters/* take it: joints without End Sites (their
// parents renumbered), offsets in metres, End Sites apart.
export function skeletonPayload(motion) {
  const keep = [];
  const newIndex = new Map();
  motion.joints.forEach((_, j) => {
    if (!(motion.sites && motion.sites[j])) { newIndex.set(j, keep.length); keep.push(j); }
  });
  const off = (j) => [0, 1, 2].map((k) => +motion.offsets[j * 3 + k].toFixed(6));
  return {
    names: keep.map((j) => motion.joints[j]),
    parents: keep.map((j) => (motion.parents[j] < 0 ? -1 : newIndex.get(motion.parents[j]))),
    offsets: keep.map(off),
    end_sites: motion.joints.map((_, j) => j).filter((j) => motion.sites && motion.sites[j]).map((j) => ({ parent: newIndex.get(motion.parents[j]), offset: off(j) })),
  };
}

// Example frames for a binding: at most `max` consecutive frames at about 30 fps from `start`
// (root position and local rotations of the joints, End Sites left out).
export function examplePayload(motion, max = 240, start = 0) {
  const stride = Math.max(1, Math.round(motion.fps / 30));
  const J = motion.joints.length;
  const keep = motion.joints.map((_, j) => j).filter((j) => !(motion.sites && motion.sites[j]));
  const root = [];
  const rotations = [];
  const g = new THREE.Quaternion();
  const pg = new THREE.Quaternion();
  for (let f = start; f < motion.frames && root.length < max; f += stride) {
    root.push([0, 1, 2].map((k) => +motion.positions[f * J * 3 + k].toFixed(5)));
    rotations.push(keep.map((j) => {
      const o = (f * J + j) * 4;
      g.fromArray(motion.rotations, o);
      const p = motion.parents[j];
      if (p >= 0) g.premultiply(pg.fromArray(motion.rotations, (f * J + p) * 4).invert());
      g.normalize();
      return [g.x, g.y, g.z, g.w].map((x) => +x.toFixed(6));
    }));
  }
  return root.length >= 2 ? { fps: motion.fps / stride, root, rotations } : null;
}
