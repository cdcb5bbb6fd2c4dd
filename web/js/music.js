// The Music tool: a tempo (BPM), a MIDI song or a recording (WAV, FLAC, Ogg, MP3), a direction
// steered with the mouse, beat flashes; a recording plays (WebAudio) in sync with the dance.
//
// Live mode (the rhythm session WebSocket, /v1/sessions/rhythm?database=ID): the page sends
// {"type":"bpm"} (the server then generates the beats), {"type":"direction","heading_deg","speed"}
// as the mouse moves and {"type":"stop"} at the end; the server sends the skeleton, then one
// {"type":"frames"} batch per beat, drawn as it comes, each flashing the beat.
// Job mode (or a MIDI song): the steering is recorded as per-beat direction keys while a local
// metronome runs, then one rhythm job is submitted; its beats flash with the result's playback,
// and the result downloads like any other. A recording is uploaded and tracked by the server (the
// job's report gives its beats); the page decodes it too (decodeAudioData) and plays it from the
// viewer's time whenever the result plays, restarting it when the two drift apart by 80 ms or the
// playback loops or is scrubbed.

import { wsUrl } from './api.js';
import { forwardKinematics } from './bvh.js';

const MAX_SPEED = 1.5; // m/s at the pad's edge
const AUDIO = /\.(wav|flac|ogg|mp3)$/i;
const DRIFT_S = 0.08; // the song restarts at the viewer's time when it drifts further

export function setupMusic(ctx) {
  const { state, $, api, runJob, guarded, dbOf, numberOf, viewer, ApiError, FloorPad, headingDeg, showError, framesText, characters } = ctx;
  const m = state.music;
  const pad = new FloorPad($('music-pad'), 2.2);
  const canvas = $('music-pad');
  let steer = { heading_deg: 0, speed: 0 };
  let metronome = null;
  let stopTimer = null;
  let resultBeats = null; // music beat times (s) of the drawn result, from its report
  let lastBeat = -1;
  let live = null;
  let audioCtx = null;
  let song = null; // { buffer: AudioBuffer, name } of the chosen recording
  let playing = null; // { source, startedAt (context time), offset (song time at start) }

  const stopSong = () => {
    if (playing) { try { playing.source.stop(); } catch (exc) { /* already ended */ } }
    playing = null;
    m.songPlaying = false;
  };
  const playSong = (t) => {
    stopSong();
    if (!song || t >= song.buffer.duration) return;
    const source = audioCtx.createBufferSource();
    source.buffer = song.buffer;
    source.connect(audioCtx.destination);
    source.start(0, Math.max(0, t));
    playing = { source, startedAt: audioCtx.currentTime, offset: Math.max(0, t) };
    m.songPlaying = true;
    m.songStarts = (m.songStarts || 0) + 1;
  };
  const songTime = () => (playing ? playing.offset + audioCtx.currentTime - playing.startedAt : null);

  const flash = () => {
    state.beats += 1;
    m.beats = state.beats;
    const el = $('beat');
    el.classList.add('on');
    setTimeout(() => el.classList.remove('on'), 90);
  };

  const redraw = () => {
    const c = pad.clear();
    c.strokeStyle = '#46505c';
    const [cx, cy] = pad.toPixels([0, 0]);
    c.beginPath(); c.arc(cx, cy, 2 * pad.scale, 0, 2 * Math.PI); c.stroke();
    if (steer.speed > 0) pad.arrow(c, [0, 0], steer.heading_deg, '#f0a030', `${steer.speed.toFixed(2)} m/s`, steer.speed / MAX_SPEED * 2);
    m.steer = { ...steer };
  };
  const aim = (ev) => {
    const [x, z] = pad.toFloor(ev.clientX, ev.clientY);
    const d = Math.hypot(x, z);
    steer = { heading_deg: headingDeg(x, z), speed: Math.min(d / 2, 1) * MAX_SPEED };
    redraw();
    if (live && live.readyState === WebSocket.OPEN) live.send(JSON.stringify({ type: 'direction', ...steer }));
  };
  canvas.addEventListener('pointermove', (ev) => { if (m.running) aim(ev); });
  canvas.addEventListener('pointerdown', aim);

  const music = async (seconds) => {
    const file = $('music-midi').files[0];
    if (file) {
      const bytes = await file.arrayBuffer();
      const info = await api.uploadFile(file.name, bytes);
      if (!AUDIO.test(file.name)) return { midi: info.name };
      audioCtx = audioCtx || new AudioContext();
      song = { buffer: await audioCtx.decodeAudioData(bytes.slice(0)), name: file.name };
      m.song = { name: file.name, duration_s: song.buffer.duration };
      return { audio: info.name };
    }
    song = null;
    m.song = null;
    return { bpm: numberOf('music-bpm', 'BPM', 30, 300), duration_s: seconds };
  };

  const stopMetronome = () => {
    clearInterval(metronome);
    clearTimeout(stopTimer);
    metronome = null;
    m.running = false;
  };

  // record mode: keys per beat while the metronome runs, then one rhythm job
  const record = async (db, bpm, seconds) => {
    m.mode = 'record';
    m.directions = [];
    let beat = 0;
    const period = 60 / bpm;
    const key = () => {
      if (steer.speed <= 0.05) return;
      const prev = m.directions[m.directions.length - 1];
      if (!prev || Math.abs(prev.heading_deg - steer.heading_deg) > 5 || Math.abs((prev.speed || 0) - steer.speed) > 0.1) {
        m.directions.push({ beat, heading_deg: +steer.heading_deg.toFixed(1), speed: +steer.speed.toFixed(2) });
      }
    };
    await new Promise((resolve) => {
      m.running = true;
      flash();
      key();
      metronome = setInterval(() => { beat += 1; flash(); key(); }, period * 1000);
      stopTimer = setTimeout(resolve, seconds * 1000);
      m.finish = resolve;
    });
    stopMetronome();
    recorded = `${beat + 1} beats · ${m.directions.length} direction keys`;
    info('synthesizing…');
    const request = { engine: 'rhythm', database: db, budget_s: 3, music: await music(seconds) };
    if (m.directions.length) request.directions = m.directions;
    resultBeats = null;
    lastBeat = -1;
    const last = await runJob('music', request);
    ended = last ? last.type : null;
    info(resultText());
  };
  // the tool's status line: what was recorded, then the job's result and how it ended (never a
  // stale "synthesizing…" once a result has arrived)
  let recorded = '';
  let ended = null;
  const info = (text) => {
    m.info = `${recorded} · ${text}`;
    $('music-info').textContent = m.info;
  };
  const resultText = () => {
    const c = state.current && state.current.tool === 'music' && !state.current.live ? state.current : null;
    const result = c ? `${c.result} · ${framesText(c.source_frames, c.source_fps, c)}` : 'no result';
    return ended ? `${ended} · ${result}` : `${result} · searching…`;
  };

  // live mode: the session streams one beat of motion per beat (generated by the server at the BPM)
  const session = (db, bpm, seconds) =>
    new Promise((resolve, reject) => {
      m.mode = 'live';
      m.frames = 0;
      m.serverBeat = -1;
      const t0 = performance.now();
      const ws = new WebSocket(wsUrl('/v1/sessions/rhythm', { database: db }));
      live = ws;
      let skeleton = null;
      let chunks = [];
      let rotChunks = [];
      let frames = 0;
      const send = (msg) => { if (ws.readyState === WebSocket.OPEN) ws.send(JSON.stringify(msg)); };
      ws.onmessage = (msg) => {
        const data = JSON.parse(msg.data);
        if (data.type === 'skeleton') {
          skeleton = data;
          m.skeleton = { joints: data.names.length, fps: data.fps, beats_per_movement: data.beats_per_movement };
          m.running = true;
          if (steer.speed > 0) send({ type: 'direction', ...steer });
          send({ type: 'bpm', bpm });
          stopTimer = setTimeout(() => send({ type: 'stop' }), seconds * 1000);
          m.finish = () => send({ type: 'stop' });
        } else if (data.type === 'frames' && skeleton) {
          const J = skeleton.parents.length;
          const globals = new Float32Array(data.root.length * J * 4);
          chunks.push(forwardKinematics(skeleton.parents, skeleton.offsets, data.root, data.rotations, globals));
          rotChunks.push(globals);
          frames += data.root.length;
          const positions = new Float32Array(frames * J * 3);
          const rotations = new Float32Array(frames * J * 4);
          let at = 0;
          for (const c of chunks) { positions.set(c, at); at += c.length; }
          at = 0;
          for (const c of rotChunks) { rotations.set(c, at); at += c.length; }
          chunks = [positions];
          rotChunks = [rotations];
          const first = m.frames === 0;
          m.frames = frames;
          m.serverBeat = data.beat;
          flash();
          viewer.loop = false;
          viewer.follow = 'result';
          const motion = { name: 'live dance', fps: data.fps, joints: skeleton.names, parents: skeleton.parents, frames, positions, rotations, offsets: new Float32Array(skeleton.offsets.flat()) };
          viewer.set('result', motion, undefined, { frame: first });
          characters.live('result', motion);
          state.current = { tool: 'music', live: true, frames, fps: data.fps, beat: data.beat };
          if (first) {
            state.timings.music = performance.now() - t0;
            viewer.seek(0);
            viewer.play();
          }
          $('music-info').textContent = `beat ${data.beat} · ${frames} frames`;
          $('sol-info').textContent = `live session · beat ${data.beat} · ${frames} frames at ${data.fps} fps`;
        } else if (data.type === 'error') {
          showError('music', new ApiError(422, 'session_error', data.message));
        } else if (data.type === 'end') {
          m.end = { frames: data.frames, beats: data.beats };
        }
      };
      ws.onclose = (ev) => {
        clearTimeout(stopTimer);
        m.running = false;
        live = null;
        viewer.loop = true;
        viewer.follow = null;
        viewer.frameAll();
        if (ev.code === 1000) resolve();
        else reject(new ApiError(ev.code === 4401 ? 401 : ev.code === 4404 ? 404 : 422, `session_closed_${ev.code}`, ev.reason || `the session closed (${ev.code})`));
      };
    });

  $('music-go').onclick = () =>
    guarded('music', async () => {
      if (m.running) throw new ApiError(0, 'already_running', 'the music is playing: press Stop first');
      const db = dbOf('music-db');
      const bpm = numberOf('music-bpm', 'BPM', 30, 300);
      const seconds = numberOf('music-seconds', 'length', 1, 600);
      viewer.clear();
      state.shownTool = 'music';
      m.started = performance.now();
      recorded = '';
      ended = null;
      if ($('music-mode').value === 'live' && !$('music-midi').files.length) await session(db, bpm, seconds);
      else await record(db, bpm, seconds);
    });
  $('music-stop').onclick = () =>
    guarded('music', async () => {
      if (!m.running || !m.finish) throw new ApiError(0, 'not_running', 'nothing is playing: Start first');
      m.finish();
    });
  redraw();

  return {
    redraw,
    // another tool was chosen: the session (or the recording) stops
    stopLive() {
      if (live && live.readyState <= WebSocket.OPEN) live.close(1000, 'another tool');
      if (metronome) stopMetronome();
    },
    // beats flash in time with the playback of a rhythm result: on the music's beats as the
    // engine placed them (its report's annotations.music_beats_s), BPM or MIDI alike
    onTime(t, isPlaying) {
      const ours = state.current && state.current.tool === 'music' && !state.current.live && !m.running;
      if (song && ours && isPlaying) {
        const at = songTime();
        if (at === null || Math.abs(at - t) > DRIFT_S) playSong(t);
      } else if (playing) stopSong();
      if (!resultBeats || m.running || !isPlaying || !state.current || state.current.tool !== 'music' || state.current.live) return;
      let lo = 0;
      let hi = resultBeats.length;
      while (lo < hi) {
        const mid = (lo + hi) >> 1;
        if (resultBeats[mid] <= t) lo = mid + 1; else hi = mid;
      }
      if (lo !== lastBeat) {
        if (lo > lastBeat && lastBeat !== -1) flash();
        lastBeat = lo; // a loop back to the start resets without a flash
      }
    },
    async onResult() {
      lastBeat = -1;
      info(resultText());
      const { job, result } = state.current;
      try {
        const report = await api.report(job, result);
        const beats = report.annotations && report.annotations.music_beats_s;
        if (Array.isArray(beats) && beats.length) {
          resultBeats = beats;
          m.resultBeats = beats.length;
        }
      } catch (exc) {
        showError('music', exc);
      }
    },
  };
}
