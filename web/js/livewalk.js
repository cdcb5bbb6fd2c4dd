// Live walk: the Path tool's "live" mode. While the mouse button is held, the performed path streams
// to the live control session (WebSocket /v1/sessions/control?database=ID&latency_s=L) and the walker
// comes back a fixed latency behind the pointer, drawn as it arrives.
//
// Protocol (docs/control.md): the server first sends {"type":"skeleton", fps, latency_s,
// latency_frames, control: "path"}; the page then sends {"type":"path","points":[[x,z],...]} —
// the path sampled at the session's fps since the last message — every SEND_MS, and {"type":"stop"}
// when the button is released; each message is answered by {"type":"frames", start, root,
// rotations} (the walker frames that became final, possibly none); after stop, the rest, then
// {"type":"end", frames, solves} and close 1000.

import { wsUrl } from './api.js';
import { forwardKinematics } from './bvh.js';

const SEND_MS = 100; // a path message every 0.1 s (3 frames at 30 fps)

// Opens a session and returns a controller: push(points) queues the path sampled so far (at
// `fps()` frames per second, [x, z] metres), stop(pathAt) ends the control after queueing
// pathAt(fps), the whole path at the session's fps (called once the session has told its fps, so
// a path drawn before the session opened is sent, not lost); `done` settles when the session closes. onFrames(positions, frames, fps, names, parents, rotations, offsets) draws the walker so far
// (positions F*J*3 and global rotations F*J*4);
// `info` collects what the tests and the status line read.
export function startLiveWalk({ database, latencyS, onFrames, onStatus, ApiError }) {
  const info = { mode: 'live', latency_s: latencyS, sent: 0, frames: 0, framesBeforeStop: 0, maxAhead: -Infinity, stopped: false, end: null, skeleton: null, errors: [] };
  const ws = new WebSocket(wsUrl('/v1/sessions/control', { database, latency_s: latencyS }));
  let skeleton = null;
  let pending = [];
  let chunks = [];
  let rotChunks = [];
  let stopAsked = false;
  let finalPath = null;
  let timer = null;
  const send = (msg) => { if (ws.readyState === WebSocket.OPEN) ws.send(JSON.stringify(msg)); };
  const flush = () => {
    if (!skeleton || !pending.length) return;
    // at most 240 frames per message (the server's limit)
    while (pending.length) {
      const batch = pending.splice(0, 240);
      send({ type: 'path', points: batch.map(([x, z]) => [+x.toFixed(4), +z.toFixed(4)]) });
      info.sent += batch.length;
    }
  };
  const push = (points) => {
    const have = info.sent + pending.length;
    if (points.length > have) pending.push(...points.slice(have));
  };
  const finish = () => {
    if (!skeleton || info.stopped) return;
    if (finalPath) push(finalPath(skeleton.fps));
    flush();
    send({ type: 'stop' });
    info.stopped = true;
    clearInterval(timer);
  };
  const done = new Promise((resolve, reject) => {
    ws.onmessage = (msg) => {
      const data = JSON.parse(msg.data);
      if (data.type === 'skeleton') {
        skeleton = data;
        info.skeleton = { joints: data.names.length, fps: data.fps, latency_frames: data.latency_frames, control: data.control };
        timer = setInterval(flush, SEND_MS);
        if (stopAsked) finish();
      } else if (data.type === 'frames' && skeleton) {
        if (!data.root.length) return;
        const J = skeleton.parents.length;
        const globals = new Float32Array(data.root.length * J * 4);
        chunks.push(forwardKinematics(skeleton.parents, skeleton.offsets, data.root, data.rotations, globals));
        rotChunks.push(globals);
        info.frames += data.root.length;
        if (!info.stopped) {
          info.framesBeforeStop = info.frames;
          // walker frames beyond what the latency allows for the path sent so far (never > 0)
          info.maxAhead = Math.max(info.maxAhead, info.frames - (info.sent - skeleton.latency_frames));
        }
        const positions = new Float32Array(info.frames * J * 3);
        const rotations = new Float32Array(info.frames * J * 4);
        let at = 0;
        for (const c of chunks) { positions.set(c, at); at += c.length; }
        at = 0;
        for (const c of rotChunks) { rotations.set(c, at); at += c.length; }
        chunks = [positions];
        rotChunks = [rotations];
        onFrames(positions, info.frames, data.fps, skeleton.names, skeleton.parents, rotations, skeleton.offsets);
        onStatus(`live · walker ${info.frames} frames, ${(info.sent - info.frames) / data.fps >= 0 ? ((info.sent - info.frames) / data.fps).toFixed(1) : '0.0'} s behind the pointer`);
      } else if (data.type === 'error') {
        info.errors.push(data.message);
        onStatus(`live · ${data.message}`);
      } else if (data.type === 'end') {
        info.end = { frames: data.frames, solves: data.solves };
      }
    };
    ws.onclose = (ev) => {
      clearInterval(timer);
      if (ev.code === 1000) resolve(info);
      else reject(new ApiError(ev.code === 4401 ? 401 : ev.code === 4404 ? 404 : 422, `session_closed_${ev.code}`, ev.reason || `the live session closed (${ev.code})`));
    };
  });
  return {
    info,
    done,
    fps: () => (skeleton ? skeleton.fps : null),
    // the points sampled so far; only those not yet queued or sent are new
    push,
    stop(pathAt = null) {
      stopAsked = true;
      finalPath = pathAt;
      if (skeleton) finish();
    },
    close() { clearInterval(timer); if (ws.readyState <= WebSocket.OPEN) ws.close(); },
  };
}
