// BVH (plain or gzip) -> the viewer's motion, with three.js's BVHLoader: per-frame global joint
// positions (F*J*3, metres, Y up) and rotations (F*J*4, x y z w) by forward kinematics of the
// loader's bones, and the skeleton's offsets (J*3, metres).
import { Quaternion } from 'three';
import { BVHLoader } from 'three/addons/loaders/BVHLoader.js';

// metres per file unit, as motion/units.py (the service reports a clip's guessed unit in ClipInfo.units)
export const METRES_PER_UNIT = { m: 1, cm: 0.01, mm: 0.001, in: 0.0254, ft: 0.3048, cmu: 0.0254 / 0.45, 'cmu-scaled': 1.28 };
// the units a guess chooses among (motion/units.py GUESSED_UNITS: cmu-scaled must be declared)
const GUESSED_UNITS = ['m', 'cm', 'mm', 'in', 'ft', 'cmu'];

async function gunzip(bytes) {
  const stream = new Blob([bytes]).stream().pipeThrough(new DecompressionStream('gzip'));
  return new Uint8Array(await new Response(stream).arrayBuffer());
}

export async function bvhText(bytes) {
  let data = new Uint8Array(bytes);
  if (data[0] === 0x1f && data[1] === 0x8b) data = await gunzip(data);
  return new TextDecoder().decode(data);
}

// bytes: ArrayBuffer of a .bvh or .bvh.gz; units: the service's unit for the clip (default: metres
// guessed from height when unknown). Returns {name, fps, joints, parents, frames, positions, sites}:
// `joints` lists every drawn point, End Sites included (named `<parent>_end`); `sites[j]` is true
// for those (skeletonJoints gives the joints alone, as the API lists a skeleton's).
export async function parseBvh(bytes, name, units) {
  const text = await bvhText(bytes);
  const { skeleton, clip } = new BVHLoader().parse(text);
  const bones = skeleton.bones;
  const J = bones.length;
  const index = new Map(bones.map((b, i) => [b, i]));
  const parents = bones.map((b) => (index.has(b.parent) ? index.get(b.parent) : -1));
  const joints = bones.map((b) => (b.name === 'ENDSITE' ? `${b.parent ? b.parent.name : ''}_end` : b.name));
  const sites = bones.map((b) => b.name === 'ENDSITE');
  const byName = new Map(bones.filter((b) => b.name !== 'ENDSITE').map((b) => [b.name, b]));
  const tracks = clip.tracks
    .map((t) => {
      const dot = t.name.lastIndexOf('.');
      return { bone: byName.get(t.name.slice(0, dot)), prop: t.name.slice(dot + 1), values: t.values, times: t.times };
    })
    .filter((t) => t.bone);
  const times = tracks.length ? tracks[0].times : [0];
  const F = times.length;
  const fps = F > 1 ? 1 / (times[1] - times[0]) : 30;
  const positions = new Float32Array(F * J * 3);
  const rotations = new Float32Array(F * J * 4);
  const offsets = new Float32Array(J * 3);
  bones.forEach((b, j) => b.position.toArray(offsets, j * 3));
  const root = bones[0];
  const q = new Quaternion();
  for (let f = 0; f < F; f++) {
    for (const t of tracks) {
      if (t.prop === 'position') t.bone.position.fromArray(t.values, f * 3);
      else t.bone.quaternion.fromArray(t.values, f * 4);
    }
    root.updateMatrixWorld(true);
    for (let j = 0; j < J; j++) {
      const e = bones[j].matrixWorld.elements;
      const o = (f * J + j) * 3;
      positions[o] = e[12];
      positions[o + 1] = e[13];
      positions[o + 2] = e[14];
      q.setFromRotationMatrix(bones[j].matrixWorld).toArray(rotations, (f * J + j) * 4);
    }
  }
  let scale = METRES_PER_UNIT[units];
  if (!scale) {
    // no unit given: the one whose standing height (vertical extent of frame 0) is closest to 1.7 m
    let lo = Infinity;
    let hi = -Infinity;
    for (let j = 0; j < J; j++) {
      lo = Math.min(lo, positions[j * 3 + 1]);
      hi = Math.max(hi, positions[j * 3 + 1]);
    }
    const h = hi - lo || 1;
    scale = GUESSED_UNITS.map((u) => METRES_PER_UNIT[u]).reduce((best, s) => (Math.abs(Math.log((h * s) / 1.7)) < Math.abs(Math.log((h * best) / 1.7)) ? s : best), 1);
  }
  for (let i = 0; i < positions.length; i++) positions[i] *= scale;
  for (let i = 0; i < offsets.length; i++) offsets[i] *= scale;
  return { name, fps, joints, parents, frames: F, positions, rotations, offsets, sites };
}

// A fast BVH reader for the service's results (thousands of frames): the same motion as parseBvh
// (position channels replace the joint's offset, as motion/bvh.py reads them; rotation channels
// are intrinsic Euler angles in file order, degrees) without building three.js animation tracks.
// Joint order: depth first, each joint followed by its End Site (as parseBvh); `sites` marks those.
export function parseBvhText(text, name, scale = 1) {
  const tok = text.split(/\s+/).filter(Boolean);
  let i = 0;
  const expect = (word) => {
    if (tok[i] !== word) throw new Error(`BVH: expected ${word} at token ${i}, got ${tok[i]}`);
    i++;
  };
  expect('HIERARCHY');
  const joints = [];
  const sites = [];
  const parents = [];
  const offsets = [];
  const channels = []; // per joint: [{slot, kind: 0 pos / 1 rot, axis 0..2}]
  let slots = 0;
  const stack = [];
  while (i < tok.length && tok[i] !== 'MOTION') {
    const t = tok[i++];
    if (t === 'ROOT' || t === 'JOINT') {
      joints.push(tok[i++]);
      sites.push(false);
      parents.push(stack.length ? stack[stack.length - 1] : -1);
      offsets.push([0, 0, 0]);
      channels.push([]);
    } else if (t === 'End') {
      i++; // Site
      joints.push(`${joints[stack[stack.length - 1]]}_end`);
      sites.push(true);
      parents.push(stack[stack.length - 1]);
      offsets.push([0, 0, 0]);
      channels.push([]);
    } else if (t === '{') {
      stack.push(joints.length - 1);
    } else if (t === '}') {
      stack.pop();
    } else if (t === 'OFFSET') {
      offsets[offsets.length - 1] = [Number(tok[i]), Number(tok[i + 1]), Number(tok[i + 2])];
      i += 3;
    } else if (t === 'CHANNELS') {
      const n = Number(tok[i++]);
      const list = channels[channels.length - 1];
      for (let k = 0; k < n; k++) {
        const c = tok[i++];
        list.push({ slot: slots++, kind: c.endsWith('position') ? 0 : 1, axis: 'XYZ'.indexOf(c[0].toUpperCase()) });
      }
    } else {
      throw new Error(`BVH: unexpected ${t} in the hierarchy`);
    }
  }
  expect('MOTION');
  expect('Frames:');
  const F = Number(tok[i++]);
  expect('Frame');
  expect('Time:');
  const dt = Number(tok[i++]);
  const J = joints.length;
  const positions = new Float32Array(F * J * 3);
  const rotations = new Float32Array(F * J * 4);
  const gq = new Float64Array(J * 4);
  const gp = new Float64Array(J * 3);
  const values = new Float64Array(slots);
  const D2R = Math.PI / 360; // half-angle radians per degree
  for (let f = 0; f < F; f++) {
    for (let s = 0; s < slots; s++) values[s] = Number(tok[i++]);
    for (let j = 0; j < J; j++) {
      let [px, py, pz] = offsets[j];
      let qx = 0, qy = 0, qz = 0, qw = 1;
      const ch = channels[j];
      let moved = false;
      for (let c = 0; c < ch.length; c++) {
        const { slot, kind, axis } = ch[c];
        const v = values[slot];
        if (kind === 0) {
          if (!moved) { px = 0; py = 0; pz = 0; moved = true; }
          if (axis === 0) px = v; else if (axis === 1) py = v; else pz = v;
        } else {
          // q = q * rotation(axis, v): intrinsic, in file order
          const s = Math.sin(v * D2R);
          const w = Math.cos(v * D2R);
          const ax = axis === 0 ? s : 0, ay = axis === 1 ? s : 0, az = axis === 2 ? s : 0;
          const nx = qw * ax + qx * w + qy * az - qz * ay;
          const ny = qw * ay - qx * az + qy * w + qz * ax;
          const nz = qw * az + qx * ay - qy * ax + qz * w;
          const nw = qw * w - qx * ax - qy * ay - qz * az;
          qx = nx; qy = ny; qz = nz; qw = nw;
        }
      }
      const p = parents[j];
      const o = (f * J + j) * 3;
      if (p < 0) {
        gp[j * 3] = px; gp[j * 3 + 1] = py; gp[j * 3 + 2] = pz;
        gq[j * 4] = qx; gq[j * 4 + 1] = qy; gq[j * 4 + 2] = qz; gq[j * 4 + 3] = qw;
      } else {
        const ax = gq[p * 4], ay = gq[p * 4 + 1], az = gq[p * 4 + 2], aw = gq[p * 4 + 3];
        // rotate the local translation by the parent's global rotation: v + 2w(a x v) + 2 a x (a x v)
        const tx = 2 * (ay * pz - az * py), ty = 2 * (az * px - ax * pz), tz = 2 * (ax * py - ay * px);
        gp[j * 3] = gp[p * 3] + px + aw * tx + (ay * tz - az * ty);
        gp[j * 3 + 1] = gp[p * 3 + 1] + py + aw * ty + (az * tx - ax * tz);
        gp[j * 3 + 2] = gp[p * 3 + 2] + pz + aw * tz + (ax * ty - ay * tx);
        gq[j * 4] = aw * qx + ax * qw + ay * qz - az * qy;
        gq[j * 4 + 1] = aw * qy - ax * qz + ay * qw + az * qx;
        gq[j * 4 + 2] = aw * qz + ax * qy - ay * qx + az * qw;
        gq[j * 4 + 3] = aw * qw - ax * qx - ay * qy - az * qz;
      }
      positions[o] = gp[j * 3] * scale;
      positions[o + 1] = gp[j * 3 + 1] * scale;
      positions[o + 2] = gp[j * 3 + 2] * scale;
      rotations.set(gq.subarray(j * 4, j * 4 + 4), (f * J + j) * 4);
    }
  }
  const offsetsM = new Float32Array(J * 3);
  offsets.forEach((o, j) => offsetsM.set(o.map((v) => v * scale), j * 3));
  return { name, fps: dt > 0 ? 1 / dt : 30, joints, parents, frames: F, positions, rotations, offsets: offsetsM, sites };
}

// Global joint positions of frames given as root positions (n, 3) and local rotations (n, J, 4)
// (x, y, z, w) on a skeleton (parents (J,), offsets (J, 3) metres): Float32Array n*J*3; with
// `globals` (a Float32Array n*J*4), the global rotations are written there too.
export function forwardKinematics(parents, offsets, root, rotations, globals = null) {
  const J = parents.length;
  const n = root.length;
  const out = new Float32Array(n * J * 3);
  const gq = new Float64Array(J * 4);
  const gp = new Float64Array(J * 3);
  for (let f = 0; f < n; f++) {
    const rot = rotations[f];
    for (let j = 0; j < J; j++) {
      const [qx, qy, qz, qw] = rot[j];
      const p = parents[j];
      if (p < 0) {
        gp[j * 3] = root[f][0]; gp[j * 3 + 1] = root[f][1]; gp[j * 3 + 2] = root[f][2];
        gq[j * 4] = qx; gq[j * 4 + 1] = qy; gq[j * 4 + 2] = qz; gq[j * 4 + 3] = qw;
      } else {
        const [px, py, pz] = offsets[j];
        const ax = gq[p * 4], ay = gq[p * 4 + 1], az = gq[p * 4 + 2], aw = gq[p * 4 + 3];
        const tx = 2 * (ay * pz - az * py), ty = 2 * (az * px - ax * pz), tz = 2 * (ax * py - ay * px);
        gp[j * 3] = gp[p * 3] + px + aw * tx + (ay * tz - az * ty);
        gp[j * 3 + 1] = gp[p * 3 + 1] + py + aw * ty + (az * tx - ax * tz);
        gp[j * 3 + 2] = gp[p * 3 + 2] + pz + aw * tz + (ax * ty - ay * tx);
        gq[j * 4] = aw * qx + ax * qw + ay * qz - az * qy;
        gq[j * 4 + 1] = aw * qy - ax * qz + ay * qw + az * qx;
        gq[j * 4 + 2] = aw * qz + ax * qy - ay * qx + az * qw;
        gq[j * 4 + 3] = aw * qw - ax * qx - ay * qy - az * qz;
      }
      out.set([gp[j * 3], gp[j * 3 + 1], gp[j * 3 + 2]], (f * J + j) * 3);
      if (globals) globals.set(gq.subarray(j * 4, j * 4 + 4), (f * J + j) * 4);
    }
  }
  return out;
}

// A parsed motion's joints without its End Sites: its skeleton as the API lists it (a clip's
// `joints`, a database summary's `skeleton.joints`), to compare skeletons by.
export function skeletonJoints(motion) {
  return motion.sites ? motion.joints.filter((_, j) => !motion.sites[j]) : motion.joints;
}
