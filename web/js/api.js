// The Segue HTTP/WebSocket API, as used by the page (same origin). Every failed call throws an
// ApiError carrying the service's {"error": {"code", "message", "details"}} body.

export class ApiError extends Error {
  constructor(status, code, message, details) {
    super(message);
    this.status = status;
    this.code = code;
    this.details = details;
  }
}

const TOKEN_KEY = 'segue.token';

export function getToken() {
  return localStorage.getItem(TOKEN_KEY) || '';
}

export function setToken(token) {
  if (token) localStorage.setItem(TOKEN_KEY, token);
  else localStorage.removeItem(TOKEN_KEY);
}

function headers(extra = {}) {
  const token = getToken();
  return token ? { ...extra, Authorization: `Bearer ${token}` } : extra;
}

function describeValidation(details) {
  // FastAPI/pydantic validation errors: [{loc, msg}, ...] -> "loc: msg; ..."
  if (!Array.isArray(details)) return '';
  return details
    .slice(0, 4)
    .map((d) => `${(d.loc || []).filter((p) => p !== 'body').join('.')}: ${d.msg}`)
    .join('; ');
}

async function failure(response) {
  let body = null;
  try {
    body = await response.json();
  } catch {
    /* not JSON */
  }
  const err = body && body.error ? body.error : null;
  if (err) {
    // the service's messages name the field and the problem already
    const message = err.message || describeValidation(err.details) || `HTTP ${response.status}`;
    return new ApiError(response.status, err.code || `http_${response.status}`, message, err.details);
  }
  if (body && body.detail) {
    const msg = typeof body.detail === 'string' ? body.detail : describeValidation(body.detail);
    return new ApiError(response.status, `http_${response.status}`, msg, body.detail);
  }
  return new ApiError(response.status, `http_${response.status}`, `${response.status} ${response.statusText}`);
}

export async function request(method, path, { json, body, query } = {}) {
  let url = path;
  if (query) {
    const q = new URLSearchParams(Object.entries(query).filter(([, v]) => v !== undefined && v !== null));
    if ([...q].length) url += `?${q}`;
  }
  const init = { method, headers: headers() };
  if (method !== 'GET' && json === undefined && body === undefined) {
    // bodyless writes (cancel, delete) declare JSON: the server refuses writes a page could forge
    init.headers = headers({ 'Content-Type': 'application/json' });
  }
  if (json !== undefined) {
    init.headers = headers({ 'Content-Type': 'application/json' });
    init.body = JSON.stringify(json);
  } else if (body !== undefined) {
    init.body = body;
  }
  let response;
  try {
    response = await fetch(url, init);
  } catch (exc) {
    throw new ApiError(0, 'network', `cannot reach the service: ${exc.message}`);
  }
  if (!response.ok) throw await failure(response);
  return response;
}

export const api = {
  health: async () => (await fetch('/healthz')).json(),
  samples: async () => (await request('GET', '/samples')).json(),
  demos: async () => (await request('GET', '/demos')).json(),
  sampleBytes: async (file) => (await request('GET', `/samples/${encodeURIComponent(file)}`)).arrayBuffer(),

  uploadClip: async (name, bytes) => {
    const form = new FormData();
    form.append('file', new Blob([bytes]), name);
    return (await request('POST', '/v1/clips', { body: form })).json();
  },
  clips: async () => (await request('GET', '/v1/clips')).json(),
  // a clip's bytes as uploaded (BVH or gzip BVH): draw clips this page did not upload; `read`: the
  // motion as the service read it, as (gzip) BVH (glTF clips, BVH files that needed warnings)
  clipBytes: async (id, read = false) =>
    (await request('GET', `/v1/clips/${encodeURIComponent(id)}/bvh${read ? '?read=true' : ''}`)).arrayBuffer(),

  files: async () => (await request('GET', '/v1/files')).json(),
  uploadFile: async (name, bytes) => {
    const form = new FormData();
    form.append('file', new Blob([bytes]), name);
    return (await request('POST', '/v1/files', { body: form })).json();
  },

  buildDatabase: async (spec) => (await request('POST', '/v1/databases', { json: spec })).json(),
  databases: async () => (await request('GET', '/v1/databases')).json(),
  database: async (id) => (await request('GET', `/v1/databases/${id}`)).json(),
  // the annotation engine's correction loop: a new database with the corrected labels
  correct: async (id, corrections) =>
    (await request('POST', `/v1/databases/${id}/corrections`, { json: corrections })).json(),

  submit: async (job) => (await request('POST', '/v1/jobs', { json: job })).json(),
  job: async (id) => (await request('GET', `/v1/jobs/${id}`)).json(),
  cancel: async (id) => (await request('POST', `/v1/jobs/${id}/cancel`)).json(),
  eventsAfter: async (id, after, wait = 0) =>
    (await request('GET', `/v1/jobs/${id}/events`, { query: { after, wait } })).json(),
  report: async (job, result) => (await request('GET', `/v1/jobs/${job}/report`, { query: { result } })).json(),
  // maxFps: the server resamples faster results down to it (the viewer's previews; downloads keep
  // the full rate)
  // character: an uploaded clip's or file's id to retarget the result onto (docs/retargeting.md),
  // events: 'contacts' etc. (GLB extras); mesh: what a GLB wears without a glTF character
  // ('body': Segue's mannequin); feet: lock, grounding or free (the server's default when empty)
  resultBlob: async (job, result, format, maxFps, character, events, mesh, feet) =>
    (await request('GET', `/v1/jobs/${job}/result`, {
      query: { format, result, max_fps: maxFps, character: character || undefined, events, mesh, feet: feet || undefined },
    })).blob(),
};

export function wsUrl(path, query = {}) {
  const token = getToken();
  const q = new URLSearchParams(Object.entries({ ...query, token: token || undefined }).filter(([, v]) => v !== undefined));
  const proto = location.protocol === 'https:' ? 'wss:' : 'ws:';
  const qs = [...q].length ? `?${q}` : '';
  return `${proto}//${location.host}${path}${qs}`;
}

const TERMINAL = new Set(['done', 'failed', 'cancelled']);

// Follow a job's events over the WebSocket, resuming with after=<last id> when the socket drops
// (up to `retries` times), then falling back to HTTP long-polling. Calls onEvent(event) for each
// event exactly once, in order; resolves with the terminal event. `handle.stop()` stops following.
export function followJob(jobId, onEvent, { retries = 5 } = {}) {
  let last = 0;
  let stopped = false;
  let socket = null;
  const handle = { stop: () => { stopped = true; if (socket) socket.close(); }, reconnects: 0 };
  handle.done = new Promise((resolve, reject) => {
    const deliver = (event) => {
      if (event.id <= last) return false;
      last = event.id;
      onEvent(event);
      if (TERMINAL.has(event.type)) {
        resolve(event);
        return true;
      }
      return false;
    };
    const poll = async () => {
      while (!stopped) {
        let events;
        try {
          // a long poll answers at the job's end or after 1 s, whichever comes first
          events = await api.eventsAfter(jobId, last, 1);
        } catch (exc) {
          reject(exc);
          return;
        }
        for (const e of events) if (deliver(e)) return;
      }
    };
    const connect = (attempt) => {
      if (stopped) return;
      let finished = false;
      socket = new WebSocket(wsUrl(`/v1/jobs/${jobId}/events`, { after: last }));
      handle.socket = socket;
      socket.onmessage = (msg) => {
        if (deliver(JSON.parse(msg.data))) finished = true;
      };
      socket.onclose = (ev) => {
        if (finished || stopped) return;
        if (ev.code === 4401 || ev.code === 4404) {
          reject(new ApiError(ev.code === 4401 ? 401 : 404, ev.code === 4401 ? 'unauthorized' : 'not_found', ev.reason || 'event stream refused'));
          return;
        }
        if (attempt < retries) {
          handle.reconnects += 1;
          setTimeout(() => connect(attempt + 1), 100 * 2 ** attempt);
        } else {
          poll();
        }
      };
    };
    connect(0);
  });
  return handle;
}
