// The movement graph of a rhythm database (GET /v1/databases/{id}/graph), drawn as SVG: one node
// per group of basic movements, with a stick figure of its representative pose, and one arrow per
// transition (width = probability). Click an arrow to cut it (click again to keep it); click a
// node to pick the source of a new transition, shift-click another to connect them (or use the
// from/to pickers and Add; Weight multiplies an existing transition's likelihood). Submit posts the edits (POST /v1/databases/{id}/graph-edits): the server
// checks the rules by what the edits change (no new dead end, no group made unreachable from a group
// that reached it) and answers the derived database, which the
// page then selects in the Music tool. Self-contained: app.js hands it a few helpers.

import { request } from './api.js';

const SVG = 'http://www.w3.org/2000/svg';
const SIZE = 360; // viewBox, px
const RING = 136; // node circle radius, px
const NODE = 21; // node radius, px

function el(name, attrs = {}, parent = null) {
  const node = document.createElementNS(SVG, name);
  for (const [k, v] of Object.entries(attrs)) node.setAttribute(k, String(v));
  if (parent) parent.appendChild(node);
  return node;
}

// A stick figure of a pose ((J, 3) metres, Y up) seen from the front, fitted into a node.
function stickFigure(pose, parents) {
  const ys = pose.map((p) => p[1]);
  const lo = Math.min(...ys);
  const hi = Math.max(...ys);
  const s = (2 * NODE - 8) / Math.max(hi - lo, 0.5);
  const mid = (lo + hi) / 2;
  let d = '';
  parents.forEach((parent, j) => {
    if (parent < 0) return;
    const a = pose[parent];
    const b = pose[j];
    d += `M${(a[0] * s).toFixed(1)} ${(-(a[1] - mid) * s).toFixed(1)}L${(b[0] * s).toFixed(1)} ${(-(b[1] - mid) * s).toFixed(1)}`;
  });
  return d;
}

export function setupGraph(ctx) {
  const { state, $, guarded, refreshDatabases } = ctx;
  const g = {
    database: null,
    groups: [],
    transitions: [],
    cuts: [], // [source, target] pending cuts
    connects: [], // [source, target, weight] pending additions
    weights: [], // [source, target, factor] pending weight changes
    from: null, // the node picked as the source of a new transition
    derived: null, // the database the last submit derived
    strongly_connected: null,
    start_only: [], // groups a dance can start in but never come back to (as learned)
    parents: [],
  };
  state.graph = g;
  const svg = $('graph-svg');
  const key = (a, b) => `${a}>${b}`;
  const has = (list, a, b) => list.some(([x, y]) => x === a && y === b);
  const drop = (list, a, b) => list.filter(([x, y]) => !(x === a && y === b));
  const exists = (a, b) => g.transitions.some((t) => t.source === a && t.target === b);

  function place(i) {
    const angle = (2 * Math.PI * i) / Math.max(g.groups.length, 1) - Math.PI / 2;
    return [SIZE / 2 + RING * Math.cos(angle), SIZE / 2 + RING * Math.sin(angle)];
  }

  // an arrow a -> b: a curve bent to its left (so a -> b and b -> a part), or a loop outside the node
  function edgePath(a, b) {
    const [x0, y0] = place(a);
    const [x1, y1] = place(b);
    if (a === b) {
      const ux = (x0 - SIZE / 2) / RING;
      const uy = (y0 - SIZE / 2) / RING;
      const cx = x0 + ux * (NODE + 9);
      const cy = y0 + uy * (NODE + 9);
      return `M${cx - uy * 6} ${cy + ux * 6}a9 9 0 1 1 0.1 0.1`;
    }
    const dx = x1 - x0;
    const dy = y1 - y0;
    const len = Math.hypot(dx, dy) || 1;
    const [ux, uy] = [dx / len, dy / len];
    const [sx, sy] = [x0 + ux * NODE, y0 + uy * NODE];
    const [ex, ey] = [x1 - ux * (NODE + 3), y1 - uy * (NODE + 3)];
    const bend = 0.12 * len;
    const [qx, qy] = [(sx + ex) / 2 + uy * bend, (sy + ey) / 2 - ux * bend];
    return `M${sx.toFixed(1)} ${sy.toFixed(1)}Q${qx.toFixed(1)} ${qy.toFixed(1)} ${ex.toFixed(1)} ${ey.toFixed(1)}`;
  }

  function draw() {
    svg.textContent = '';
    const defs = el('defs', {}, svg);
    for (const [id, color] of [['graph-arrow', '#8a939e'], ['graph-arrow-add', '#7ccf7c'], ['graph-arrow-cut', '#ff6b6b']]) {
      const m = el('marker', { id, viewBox: '0 0 10 10', refX: 9, refY: 5, markerWidth: 5, markerHeight: 5, orient: 'auto' }, defs);
      el('path', { d: 'M0 0L10 5L0 10z', fill: color }, m);
    }
    const edges = el('g', { class: 'edges' }, svg);
    const arrow = (a, b, cls, title, width) => {
      const d = edgePath(a, b);
      const cut = cls.includes('cut');
      const added = cls.includes('added');
      const marker = cut ? 'graph-arrow-cut' : added ? 'graph-arrow-add' : 'graph-arrow';
      el('path', { d, class: `line ${cls}`, 'stroke-width': width, 'marker-end': `url(#${marker})` }, edges);
      const hit = el('path', { d, class: `edge ${cls}`, 'data-source': a, 'data-target': b }, edges);
      el('title', {}, hit).textContent = title;
      hit.addEventListener('click', () => toggle(a, b));
    };
    for (const t of g.transitions) {
      const w = g.weights.find(([x, y]) => x === t.source && y === t.target);
      const cls = `${t.learned ? 'learned' : 'added'}${has(g.cuts, t.source, t.target) ? ' cut' : ''}${w ? ' weighted' : ''}`;
      const title = `${t.source} → ${t.target}: P ${t.probability.toFixed(3)} · kinematic ${t.kinematic.toFixed(3)} · behavioural ${t.behavioural.toFixed(3)}${t.learned ? '' : ' (added)'}${w ? ` · to be weighted ×${w[2]}` : ''}\nclick to cut`;
      arrow(t.source, t.target, cls, title, (0.6 + 5 * t.probability).toFixed(2));
    }
    for (const [a, b, w] of g.connects) arrow(a, b, 'added pending', `${a} → ${b}: to be added (weight ${w})\nclick to drop`, 2);
    const nodes = el('g', { class: 'nodes' }, svg);
    for (const grp of g.groups) {
      const [x, y] = place(grp.id);
      const node = el('g', { class: `node${g.from === grp.id ? ' from' : ''}`, 'data-group': grp.id, transform: `translate(${x.toFixed(1)} ${y.toFixed(1)})` }, nodes);
      el('circle', { r: NODE }, node);
      el('path', { class: 'figure', d: stickFigure(grp.pose, g.parents) }, node);
      el('text', { x: NODE - 2, y: -NODE + 6 }, node).textContent = String(grp.id);
      const r = grp.representative;
      el('title', {}, node).textContent = `group ${grp.id}: ${grp.size} movement${grp.size === 1 ? '' : 's'}\ne.g. ${r.clip}${r.mirrored ? ' (mirrored)' : ''} frames ${r.start_frame}–${r.end_frame} (${r.start_s.toFixed(2)}–${r.end_s.toFixed(2)} s)\nclick: source of a new transition · shift-click: connect from the source`;
      node.addEventListener('click', (ev) => pick(grp.id, ev.shiftKey));
    }
    const edits = g.cuts.length + g.connects.length + g.weights.length;
    $('graph-submit').disabled = !edits;
    $('graph-info').textContent = g.database
      ? `${g.groups.length} groups · ${g.transitions.length} transitions${g.strongly_connected ? '' : ' · NOT strongly connected'}${g.start_only.length ? ` (start-only groups ${g.start_only.join(', ')})` : ''} · ${edits} pending edit${edits === 1 ? '' : 's'}`
      : '';
  }

  function toggle(a, b) {
    ctx.clearError('graph');
    if (has(g.connects, a, b)) g.connects = drop(g.connects, a, b);
    else if (has(g.cuts, a, b)) g.cuts = drop(g.cuts, a, b);
    else { g.cuts.push([a, b]); g.weights = drop(g.weights, a, b); }
    draw();
  }

  function factor() {
    const w = Number($('graph-weight').value);
    if (!(w > 0) || !Number.isFinite(w)) throw new Error('the weight must be a positive number');
    return w;
  }

  function connect(a, b) {
    ctx.clearError('graph');
    const w = factor();
    if (exists(a, b)) {
      if (has(g.cuts, a, b)) g.cuts = drop(g.cuts, a, b); // adding back what is being cut: keep it
      else throw new Error(`the transition ${a} → ${b} exists already (weight it instead)`);
    } else {
      g.connects = [...drop(g.connects, a, b), [a, b, w]];
    }
    draw();
  }

  // multiply an existing transition's likelihood (or set a pending addition's weight)
  function weigh(a, b) {
    ctx.clearError('graph');
    const w = factor();
    if (has(g.connects, a, b)) g.connects = g.connects.map((c) => (c[0] === a && c[1] === b ? [a, b, w] : c));
    else if (!exists(a, b) || has(g.cuts, a, b)) throw new Error(`there is no transition ${a} → ${b} to weight (Add it)`);
    else g.weights = [...drop(g.weights, a, b), [a, b, w]];
    draw();
  }

  function pick(id, shift) {
    if (shift && g.from !== null) {
      guarded('graph', async () => connect(g.from, id));
      return;
    }
    g.from = g.from === id ? null : id;
    if (g.from !== null) $('graph-from').value = String(id);
    draw();
  }

  function fillPickers() {
    for (const sel of [$('graph-from'), $('graph-to')]) {
      sel.textContent = '';
      for (const grp of g.groups) sel.add(new Option(`group ${grp.id}`, String(grp.id)));
    }
  }

  async function load(id = $('music-db').value) {
    if (!id) throw new Error('choose a rhythm database first');
    const graph = await (await request('GET', `/v1/databases/${encodeURIComponent(id)}/graph`)).json();
    Object.assign(g, {
      database: graph.database,
      groups: graph.groups,
      transitions: graph.transitions,
      strongly_connected: graph.strongly_connected,
      start_only: graph.start_only_groups || [],
      derived_from: graph.derived_from,
      parents: graph.parents,
      cuts: [],
      connects: [],
      weights: [],
      from: null,
    });
    fillPickers();
    draw();
  }

  async function submit() {
    const edits = [
      ...g.cuts.map(([source, target]) => ({ op: 'cut', source, target })),
      ...g.connects.map(([source, target, weight]) => ({ op: 'connect', source, target, weight })),
      ...g.weights.map(([source, target, weight]) => ({ op: 'weight', source, target, weight })),
    ];
    const info = await (await request('POST', `/v1/databases/${encodeURIComponent(g.database)}/graph-edits`, { json: { edits } })).json();
    g.derived = info.id;
    await refreshDatabases();
    await load(info.id);
    const sel = $('music-db');
    sel.value = info.id; // the Music tool now dances the derived database
    sel.dispatchEvent(new Event('change'));
    $('graph-info').textContent += ` · derived database ${info.id.slice(0, 12)} selected`;
  }

  $('graph-load').onclick = () => guarded('graph', () => load());
  $('graph-add').onclick = () => guarded('graph', async () => connect(Number($('graph-from').value), Number($('graph-to').value)));
  $('graph-weigh').onclick = () => guarded('graph', async () => weigh(Number($('graph-from').value), Number($('graph-to').value)));
  $('graph-reset').onclick = () => { g.cuts = []; g.connects = []; g.weights = []; g.from = null; ctx.clearError('graph'); draw(); };
  $('graph-submit').onclick = () => guarded('graph', submit);
  $('music-db').addEventListener('change', () => {
    if (g.database && $('music-db').value && $('music-db').value !== g.database && $('graph-view').open) guarded('graph', () => load());
  });
  $('graph-view').addEventListener('toggle', () => {
    if ($('graph-view').open && !g.database && $('music-db').value) guarded('graph', () => load());
  });
  return { load, draw };
}
