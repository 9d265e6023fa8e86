// valvebench web dashboard (docs/web.md). A page of hash routes over the server's /api gateway, which is the
// BenchService itself: this file holds no rule (validation, roles, limits are the server's answers).
'use strict';

const TOKEN_KEY = 'valvebench.token';
const $ = (sel, root) => (root || document).querySelector(sel);
let cleanups = [];  // run when the route changes: timers, EventSources, charts

function el(tag, attrs, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (v === undefined || v === null || v === false) continue;
    if (k.startsWith('on')) e.addEventListener(k.slice(2), v);
    else if (k === 'text') e.textContent = v;
    else e.setAttribute(k, v === true ? '' : v);
  }
  for (const c of children.flat(Infinity)) if (c !== null && c !== undefined) e.append(c instanceof Node ? c : String(c));
  return e;
}

// A number from protobuf JSON, which writes NaN and infinities as strings ("NaN"): null (a gap) for those.
function num(v) { return typeof v === 'number' && isFinite(v) ? v : null; }

function fmt(v, digits) {
  if (v === null || v === undefined || v === '' || (typeof v === 'number' && !isFinite(v))) return '–';
  const x = Number(v);
  if (Number.isInteger(x) && Math.abs(x) < 1e9) return String(x);
  return String(parseFloat(x.toPrecision(digits || 4)));
}
// Local time with the zone, UTC on hover (lists.js timeCell).
function when(unix_s) { return timeCell(unix_s); }
function duration(s) {
  if (s === null || s === undefined || !isFinite(s)) return '–';
  if (s < 60) return s.toFixed(1) + ' s';
  if (s < 3600) return Math.floor(s / 60) + ' min ' + Math.round(s % 60) + ' s';
  return (s / 3600).toFixed(1) + ' h';
}
function statusCell(s) { return el('span', {class: 'status-' + s, text: s}); }
function runLink(id, text) { return el('a', {href: '#/run/' + id, text: text || ('#' + id)}); }

// ---- session: the token in sessionStorage, sent as a bearer header; /api/login sets the cookie SSE needs.
function token() { return sessionStorage.getItem(TOKEN_KEY) || ''; }

class ApiError extends Error {
  constructor(status, code, message) { super(message); this.status = status; this.code = code; }
}

async function api(method, path, body) {
  const opts = {method, headers: {}};
  if (token()) opts.headers['Authorization'] = 'Bearer ' + token();
  if (body !== undefined) {
    opts.headers['Content-Type'] = 'application/json';
    opts.body = JSON.stringify(body);
  }
  let res;
  try { res = await fetch(path, opts); } catch (e) {
    setConnected(false, e.message);  // the server went away: a banner, not "TypeError: Failed to fetch"
    throw new ApiError(0, 'UNAVAILABLE', 'the server does not answer (' + e.message + ')');
  }
  setConnected(true);
  const text = await res.text();
  let data = null;
  try { data = text ? JSON.parse(text) : null; } catch (e) { data = null; }
  if (!res.ok) {
    const code = data && data.code ? data.code : 'HTTP_' + res.status;
    const message = data && data.message ? data.message : text || res.statusText;
    throw new ApiError(res.status, code, message);
  }
  return data;
}

function flash(message, ok) {
  const f = $('#flash');
  f.textContent = message;
  f.className = ok ? 'ok' : '';
  f.hidden = !message;
}
function errorText(e) { return e instanceof ApiError ? e.code + ': ' + e.message : String(e); }
function showError(e, where) {
  if (e instanceof ApiError && e.status === 0 && !where) return;  // the disconnected banner says it
  const text = errorText(e);
  if (where) where.replaceChildren(el('p', {class: 'error', text}));
  else flash(text);
  if (e instanceof ApiError && e.status === 401) showLoggedOut();
}

async function login(t) {
  sessionStorage.setItem(TOKEN_KEY, t);
  try {
    await api('POST', '/api/login', {token: t});
  } catch (e) {
    sessionStorage.removeItem(TOKEN_KEY);
    showLoggedOut();
    flash(errorText(e));
    return false;
  }
  await loadSession();
  showLoggedIn();
  flash('');
  return true;
}
function showLoggedIn() { $('#login').hidden = true; $('#session').hidden = false; }
function showLoggedOut() { $('#login').hidden = false; $('#session').hidden = true; me = null; document.body.dataset.role = ''; }

// ---- charts (dygraphs, Debian's libjs-dygraphs, embedded in the server)
// The gate's axis: 0 and 1, nothing between.
const GATE_AXIS = {valueRange: [-0.05, 1.3], ticker: () => [{v: 0, label: '0'}, {v: 1, label: '1'}]};

// A page left while its data was on the way draws nothing (its divs are no longer in the document).
const DETACHED = {updateOptions() {}, destroy() {}};
function chart(div, rows, labels, opts) {
  if (!div.isConnected) return DETACHED;
  const g = new Dygraph(div, rows.length ? rows : [[0].concat(labels.slice(1).map(() => null))], Object.assign({
    labels, legend: 'always', labelsSeparateLines: false, connectSeparatedPoints: false,
    xlabel: 't [s]', animatedZooms: false, labelsKMB: false, digitsAfterDecimal: 4,
  }, chartTheme(), opts || {}));
  cleanups.push(() => g.destroy());
  return g;
}

// Rows [t, a, b, ...] of several runs merged on one time axis (nulls where a run has no sample).
function mergeSeries(series) {
  const map = new Map();
  series.forEach((s, k) => {
    for (const [t, v] of s) {
      let row = map.get(t);
      if (!row) { row = new Array(series.length + 1).fill(null); row[0] = t; map.set(t, row); }
      row[k + 1] = v;
    }
  });
  return Array.from(map.values()).sort((a, b) => a[0] - b[0]);
}

// ---- routes
const routes = [
  [/^\/?$/, pageLab],
  [/^\/runs$/, pageRuns],
  [/^\/run\/(\d+)$/, pageRun],
  [/^\/submit$/, pageSubmit],
  [/^\/compare$/, pageCompare],
  [/^\/nights$/, pageNights],
  [/^\/diagnosis$/, pageDiagnosis],
];

function route() {
  for (const c of cleanups) { try { c(); } catch (e) { /* already gone */ } }
  cleanups = [];
  if (Date.now() > keepFlashUntil) flash('');  // a result to show across re-renders (cancel) stays a while
  const hash = location.hash.replace(/^#/, '') || '/';
  const [path, query] = hash.split('?');
  const params = new URLSearchParams(query || '');
  for (const a of document.querySelectorAll('#nav a'))
    a.classList.toggle('active', a.getAttribute('href') === '#' + (path === '' ? '/' : path));
  const main = $('#main');
  if (!token()) { main.replaceChildren(el('p', {text: 'Enter a token (viewer, operator or admin) to follow the lab.'})); return; }
  for (const [re, fn] of routes) {
    const m = path.match(re);
    if (m) { fn(main, m, params); return; }
  }
  main.replaceChildren(el('p', {class: 'error', text: 'No such page: ' + hash}));
}

function every(ms, fn) {
  let stopped = false, timer = null;
  const tick = async () => {
    if (stopped) return;
    try { await fn(); } catch (e) { showError(e); }
    if (!stopped) timer = setTimeout(tick, ms);
  };
  cleanups.push(() => { stopped = true; clearTimeout(timer); });
  tick();
}

// ---- live traces: WatchRun through Server-Sent Events
function liveView(runId, box, onEnd) {
  const counter = el('span', {class: 'muted live-count', text: '0 samples'});
  const status = el('span', {class: 'live-status', text: '…'});
  const cur = el('div', {class: 'chart-small'}), pos = el('div', {class: 'chart-small'});
  box.append(el('div', {class: 'actions'}, 'status ', status, ' · ', counter), el('div', {class: 'charts'}, cur, pos));
  const rowsI = [], rowsX = [];
  const gI = chart(cur, [], ['t [s]', 'i_A', 'ref', 'gate'], {ylabel: 'A', series: {gate: {axis: 'y2', stepPlot: true}},
    axes: {y2: GATE_AXIS}, y2label: 'gate'});
  const gX = chart(pos, [], ['t [s]', 'x_m'], {ylabel: 'm'});
  let dirty = false, n = 0, lastT = -Infinity;
  const timer = setInterval(() => {
    if (!dirty) return;
    dirty = false;
    gI.updateOptions({file: rowsI});
    gX.updateOptions({file: rowsX});
  }, 250);
  const es = new EventSource('/api/runs/' + runId + '/events?rate_Hz=200');
  const MAX = 20000;
  es.addEventListener('run', (ev) => {
    const e = JSON.parse(ev.data);
    status.replaceChildren(statusCell(e.status), ' ' + Math.round(100 * (e.progress || 0)) + ' %');
    for (const s of e.samples || []) {
      // The server writes fields at zero too (proto3 JSON would leave them out: t_s = 0, x_m = 0 at rest); a
      // missing one is still read as 0, and NaN (no reference) arrives as "NaN".
      const t = typeof s.t_s === 'number' ? s.t_s : 0;
      if (!(t > lastT)) continue;  // a reconnected stream starts over from the run's buffer
      lastT = t;
      rowsI.push([t, s.i_A === undefined ? 0 : num(s.i_A), s.ref === undefined ? 0 : num(s.ref), num(s.gate || 0)]);
      rowsX.push([t, s.x_m === undefined ? 0 : num(s.x_m)]);
      n++;
    }
    if (rowsI.length > MAX) { rowsI.splice(0, rowsI.length - MAX); rowsX.splice(0, rowsX.length - MAX); }
    counter.textContent = n + ' samples';
    counter.dataset.samples = String(n);
    dirty = rowsI.length > 0;  // a queued run's events carry no samples; dygraphs refuses an empty file
  });
  es.addEventListener('end', (ev) => {
    es.close();
    const e = JSON.parse(ev.data);
    status.replaceChildren(statusCell(e.status));
    if (onEnd) onEnd(e.status);
  });
  es.addEventListener('error', (ev) => {
    if (ev.data) { es.close(); status.replaceChildren(el('span', {class: 'error', text: JSON.parse(ev.data).message})); }
    // A refusal (429: too many live views open) closes the EventSource for good: say so.
    else if (es.readyState === EventSource.CLOSED) {
      status.replaceChildren(el('span', {class: 'error', text: 'live view refused (too many open); reload to retry'}));
    }
  });
  cleanups.push(() => { es.close(); clearInterval(timer); });
}

async function rerun(id) {
  try {
    const r = await api('POST', '/api/runs/' + id + '/rerun');
    flash('re-run of run ' + id + ' queued as run ' + r.run_ids.join(', ') + ' (batch ' + r.batch_id + ')', true);
    location.hash = '#/run/' + r.run_ids[0];
  } catch (e) { showError(e); }
}

// ---- Run page: spec, conditions, history, metrics with units, traces with zoom, export links, live view
async function pageRun(main, m) {
  const id = m[1];
  main.replaceChildren(el('h1', {text: 'Run ' + id}), el('p', {class: 'muted', text: 'loading…'}));
  let data;
  try { data = await api('GET', '/api/runs/' + id); } catch (e) { showError(e, main); return; }
  const r = data.run, units = data.metric_units || {}, cu = data.channel_units || {};
  const ended = !['QUEUED', 'RUNNING'].includes(r.status);
  const actions = el('div', {class: 'actions'},
    ended || !canCancel(r) ? null : el('button', {class: 'danger', id: 'cancel', onclick: () => cancelRun(id, r.submitter).then((ok) => ok && route()), text: 'Cancel'}),
    canOperate() ? el('button', {id: 'rerun', onclick: () => rerun(id), text: 'Re-run'}) : null,
    ended ? el('a', {href: '/api/runs/' + id + '/trace.csv', id: 'export-csv', text: 'trace CSV'}) : null,
    ended ? el('a', {href: '/api/runs/' + id + '/trace.h5', id: 'export-h5', text: 'HDF5'}) : null,
    ended ? el('a', {href: '/api/runs/' + id + '/trace.mat', id: 'export-mat', text: 'MAT'}) : null,
    el('a', {href: '/api/runs/' + id, id: 'export-json', text: 'run JSON'}),
    el('a', {href: '#/compare?runs=' + id, text: 'compare'}),
    el('a', {href: '#/runs?batch=' + r.batch_id, text: 'batch ' + r.batch_id}));
  const c = (r.spec && r.spec.conditions) || {};
  const kv = el('div', {class: 'kv'});
  for (const [k, v] of [['name', r.name], ['status', statusCell(r.status)], ['reason', r.reason || '–'],
    ['controller', r.controller], ['bench', r.bench || 'any'], ['submitter', r.submitter],
    ['priority', String(r.priority || 0)], ['tags', (r.tags || []).join(', ') || '–'],
    ['conditions.supply_V', fmt(c.supply_V) + ' V'], ['conditions.supply_pressure_Pa', fmt(c.supply_pressure_Pa || 0) + ' Pa'],
    ['duration_s', fmt(r.spec && r.spec.duration_s) + ' s'], ['submitted', when(r.submitted_unix_s)],
    ['started', when(r.started_unix_s)], ['finished', when(r.finished_unix_s)],
    ['progress', Math.round(100 * (r.progress || 0)) + ' %']]) kv.append(el('div', {text: k}), el('div', {}, v));
  const history = el('table', {class: 'wide'}, el('tr', {}, ['time', 'status', 'reason'].map((h) => el('th', {text: h}))),
    (r.history || []).map((h) => el('tr', {}, el('td', {}, when(h.at_unix_s)), el('td', {}, statusCell(h.status)),
      el('td', {text: h.reason || ''}))));
  const metricNames = Object.keys(r.metrics || {}).sort();
  const metrics = metricNames.length === 0 ? el('p', {class: 'muted', text: 'No metrics (yet).'}) :
    el('table', {id: 'metrics'}, el('tr', {}, ['metric', 'value', 'unit'].map((h) => el('th', {text: h}))),
      metricNames.map((k) => el('tr', {}, el('td', {text: k}), el('td', {class: 'num', text: fmt(r.metrics[k], 6)}),
        el('td', {text: units[k] || ''}))));
  const traces = el('section', {id: 'traces'}, el('h2', {text: 'Traces'}));
  main.replaceChildren(el('h1', {}, 'Run ' + id + ' ', statusCell(r.status)), actions,
    el('div', {class: 'grid2'},
      el('section', {}, el('h2', {text: 'Run'}), kv),
      el('section', {}, el('h2', {text: 'History'}), el('div', {class: 'fit'}, history),
        el('h2', {text: 'Metrics'}), el('div', {class: 'scroll'}, metrics))),
    traces,
    el('section', {}, el('h2', {text: 'Spec (exact, single run)'}), el('pre', {text: JSON.stringify(r.spec, null, 2)})));
  if (!ended) {
    liveView(id, traces, () => setTimeout(route, 300));
    return;
  }
  await traceCharts(id, traces, cu);
}

// The recorded trace, min/max-decimated by the server to ~4000 rows; zooming refetches the visible window at
// full resolution (double-click: back to the whole run).
async function traceCharts(id, box, cu) {
  const note = el('p', {class: 'muted', text: 'loading trace…'});
  box.append(note);
  let t;
  try { t = await api('GET', '/api/runs/' + id + '/trace?max_points=4000'); } catch (e) { showError(e, note); return; }
  const col = (name) => t.channels.indexOf(name);
  const groups = [
    [['i_A', 'ref'], (cu.ref === 'A' || !cu.ref) ? 'A' : 'A (ref: ' + cu.ref + ')'],
    [['x_m'].concat(cu.ref === 'm' ? ['ref'] : []), 'm'],
    [['gate', 'v_coil_V'], 'V'],
  ];
  note.textContent = t.total_samples + ' samples at ' + fmt(1 / t.sample_period_s) + ' Hz' +
    (t.decimated ? ' (shown as a min/max envelope; drag to zoom for every sample, double-click to reset)' : '');
  const graphs = [];
  let syncing = false;
  for (const [names, unit] of groups) {
    const present = names.filter((n) => col(n) >= 0 && !(n === 'ref' && unit === 'A' && cu.ref === 'm'));
    if (present.length === 0) continue;
    const pick = (rows) => rows.map((row) => [row[0]].concat(present.map((n) => row[col(n) + 1])));
    const div = el('div', {class: 'chart trace-chart'});
    box.append(div);
    const withGate = present.includes('gate') && present.length > 1;
    const g = chart(div, pick(t.rows), ['t [s]'].concat(present), {ylabel: unit,
      series: withGate ? {gate: {stepPlot: true, axis: 'y2'}} : {},
      axes: withGate ? {y2: GATE_AXIS} : {}, y2label: withGate ? 'gate' : undefined,
      zoomCallback: async (lo, hi) => {
        if (syncing) return;
        syncing = true;
        for (const o of graphs) if (o.g !== g) o.g.updateOptions({dateWindow: [lo, hi]});
        syncing = false;
        const full = lo <= t.rows[0][0] && hi >= t.rows[t.rows.length - 1][0];
        try {
          const w = full ? t : await api('GET', '/api/runs/' + id + '/trace?max_points=4000&t_from_s=' + lo + '&t_to_s=' + hi);
          for (const o of graphs) o.g.updateOptions({file: o.pick(w.rows), dateWindow: full ? null : [lo, hi]});
        } catch (e) { showError(e); }
      }});
    graphs.push({g, pick});
  }
}

// ---- Compare: overlays on shared axes, error traces, RMSE/effort scatter with the Pareto front
async function pageCompare(main, m, params) {
  const input = el('input', {id: 'compare-runs', type: 'text', size: 30, placeholder: 'run ids, e.g. 1,2,3',
    value: params.get('runs') || ''});
  const form = el('form', {class: 'actions', onsubmit: (ev) => {
    ev.preventDefault();
    location.hash = '#/compare?runs=' + input.value.replace(/\s+/g, '');
  }}, 'runs ', input, el('button', {type: 'submit', text: 'Compare'}), el('span', {class: 'muted', text: 'or pick runs on the Runs page'}));
  const body = el('div');
  main.replaceChildren(el('h1', {text: 'Compare'}), el('section', {}, form), body);
  const q = params.get('batch') ? 'batch_id=' + encodeURIComponent(params.get('batch'))
    : params.get('runs') ? 'runs=' + encodeURIComponent(params.get('runs')) : null;
  if (!q) return;
  let cmp, ids;
  try {
    cmp = await api('GET', '/api/compare?' + q);
    if (params.get('batch')) {
      const l = await api('GET', '/api/runs?page_size=50&batch_id=' + encodeURIComponent(params.get('batch')));
      ids = (l.runs || []).map((r) => String(r.id));
    } else ids = params.get('runs').split(',');
  } catch (e) { showError(e, body); return; }
  const c = cmp.comparison, units = cmp.units || {};
  const cols = c.columns || [];
  const table = el('table', {id: 'comparison'},
    el('tr', {}, el('th', {text: 'rank'}), el('th', {text: 'name'}), el('th', {text: 'controller'}), el('th', {text: 'runs'}),
      el('th', {text: 'Pareto'}), cols.map((k) => el('th', {class: 'num', text: k + (units[k] ? ' [' + units[k] + ']' : '')}))),
    (c.rows || []).map((r) => el('tr', {}, el('td', {text: r.rank || '–'}), el('td', {text: r.name}),
      el('td', {text: r.controller}), el('td', {text: (r.runs || 0) + (r.failed ? ' (' + r.failed + ' failed)' : '')}),
      el('td', {text: r.pareto ? 'yes' : ''}),
      cols.map((k) => { const s = (r.metrics || {})[k]; return el('td', {class: 'num', text: s ? fmt(s.mean) + (s.n > 1 ? ' ± ' + fmt(s.spread, 2) : '') : '–'}); }))));
  const scatter = el('div', {class: 'chart', id: 'pareto'});
  const overI = el('div', {class: 'chart', id: 'overlay-current'});
  const overX = el('div', {class: 'chart', id: 'overlay-position'});
  const errs = el('div', {class: 'chart', id: 'overlay-error'});
  body.append(el('section', {}, el('h2', {text: 'Metrics (rank by ' + (c.rank_metric || 'rmse') + ')'}),
    el('div', {class: 'actions downloads'}, 'download ', el('a', {href: '/api/compare.csv?' + q, id: 'export-compare-csv', text: 'CSV'}),
      el('a', {href: '/api/compare.json?' + q, id: 'export-compare-json', text: 'JSON'})), el('div', {class: 'scroll'}, table)),
    el('section', {}, el('h2', {text: c.rank_metric + ' vs ' + c.effort_metric + ' (Pareto front joined)'}), scatter),
    el('section', {}, el('h2', {text: 'Overlays on shared axes'}), overI, overX),
    el('section', {}, el('h2', {text: 'Tracking error (controlled variable − reference)'}), errs));
  // Scatter: one series per row; the front as a line through the Pareto rows.
  const pts = (c.rows || []).map((r) => ({name: r.name, x: num(((r.metrics || {})[c.effort_metric] || {}).mean),
    y: num(((r.metrics || {})[c.rank_metric] || {}).mean), pareto: r.pareto})).filter((p) => p.x !== null && p.y !== null);
  if (pts.length) {
    const names = pts.map((p) => p.name);
    const rows = pts.map((p, k) => { const row = [p.x].concat(new Array(pts.length + 1).fill(null)); row[k + 1] = p.y; return row; });
    const front = pts.filter((p) => p.pareto).sort((a, b) => a.x - b.x);
    for (const p of front) { const row = [p.x].concat(new Array(pts.length + 1).fill(null)); row[pts.length + 1] = p.y; rows.push(row); }
    rows.sort((a, b) => a[0] - b[0]);
    const series = {'Pareto front': {drawPoints: false, strokeWidth: 1.5, connectSeparatedPoints: true}};
    for (const n of names) series[n] = {strokeWidth: 0, drawPoints: true, pointSize: 5};
    chart(scatter, rows, [c.effort_metric].concat(names, ['Pareto front']), {xlabel: c.effort_metric + ' [' + (units[c.effort_metric] || '') + ']',
      ylabel: c.rank_metric + ' [' + (units[c.rank_metric] || '') + ']', series, drawPoints: true, strokeWidth: 0,
      connectSeparatedPoints: false, legend: 'follow', labelsSeparateLines: true});
  } else scatter.replaceChildren(el('p', {class: 'muted', text: 'No run has both metrics.'}));
  // Overlays: each run's trace (decimated), merged on one time axis.
  const shown = ids.slice(0, 12);
  try {
    const traces = await Promise.all(shown.map((id) => Promise.all([api('GET', '/api/runs/' + id),
      api('GET', '/api/runs/' + id + '/trace?max_points=3000')])));
    const labels = shown.map((id, k) => '#' + id + ' ' + traces[k][0].run.name);
    const series = (name) => traces.map(([, t]) => { const j = t.channels.indexOf(name); return j < 0 ? [] : t.rows.map((r) => [r[0], r[j + 1]]); });
    chart(overI, mergeSeries(series('i_A')), ['t [s]'].concat(labels), {ylabel: 'i_A [A]'});
    chart(overX, mergeSeries(series('x_m')), ['t [s]'].concat(labels), {ylabel: 'x_m [m]'});
    const err = traces.map(([run, t]) => {
      const refUnit = (run.channel_units || {}).ref;
      const y = t.channels.indexOf(refUnit === 'm' ? 'x_m' : 'i_A'), ref = t.channels.indexOf('ref');
      if (!refUnit || y < 0 || ref < 0) return [];
      return t.rows.map((r) => [r[0], (r[y + 1] === null || r[ref + 1] === null) ? null : r[y + 1] - r[ref + 1]]);
    });
    if (err.some((e) => e.length)) chart(errs, mergeSeries(err), ['t [s]'].concat(labels), {ylabel: 'error [A or m]'});
    else errs.replaceChildren(el('p', {class: 'muted', text: 'No run has a reference.'}));
    if (ids.length > shown.length) overI.before(el('p', {class: 'muted', text: 'first ' + shown.length + ' of ' + ids.length + ' runs shown'}));
  } catch (e) { showError(e, overI); }
}

// ---- Diagnosis: the imported measured runs by dataset; "diagnose" runs the sim-to-real gap diagnosis on the
// server (DiagnoseRuns, the same as benchctl diagnose --runs; docs/web.md "Diagnosis").
async function runDiagnosis(ids, out) {
  out.replaceChildren(el('p', {class: 'muted', text: 'Diagnosing ' + ids.length + ' runs on the server (seconds to a minute) …'}));
  try {
    const d = await api('GET', '/api/diagnose?runs=' + ids.join(','));
    const v = d.diagnosis || {};
    out.replaceChildren(
      el('p', {}, el('strong', {text: 'Verdict: '}), el('span', {class: 'verdict', text: String(v.verdict || '–')})),
      el('pre', {class: 'report', text: d.report}));
  } catch (e) { showError(e, out); }
}

async function pageDiagnosis(main) {
  const box = el('div', {class: 'scroll'});
  const out = el('div', {id: 'diagnosis-report', class: 'scroll'});
  main.replaceChildren(el('h1', {text: 'Diagnosis'}), el('section', {},
    el('p', {}, 'The sim-to-real gap diagnosis of stored measured runs: where they depart from the model, which ' +
      'unmodelled effect explains it and how far it closes the gap on held-out runs (docs/gap.md). It runs on the ' +
      'server, as ', el('code', {text: 'benchctl diagnose --runs ID,ID,…'}), ' does.'), box, out));
  try {
    const l = await api('GET', '/api/runs?tag=imported&page_size=1000');
    const byBatch = new Map();
    for (const r of l.runs || []) {
      if (!byBatch.has(r.batch_id)) byBatch.set(r.batch_id, []);
      byBatch.get(r.batch_id).push(r);
    }
    box.replaceChildren(byBatch.size === 0 ? el('p', {class: 'muted', text: 'No imported runs (benchctl import DIR).'}) :
      el('table', {}, el('tr', {}, ['batch', 'dataset', 'runs', 'fit / holdout', 'diagnosis', ''].map((h) => el('th', {text: h}))),
        Array.from(byBatch.entries()).map(([b, runs]) => {
          const ds = ((runs[0].tags || []).find((t) => t.startsWith('dataset:')) || '').slice(8);
          const fit = runs.filter((r) => r.split === 'fit').length, hold = runs.filter((r) => r.split === 'holdout').length;
          return el('tr', {}, el('td', {}, el('a', {href: '#/runs?batch=' + b, text: b})), el('td', {text: ds}),
            el('td', {class: 'num', text: String(runs.length)}), el('td', {text: fit + ' / ' + hold}),
            el('td', {}, el('button', {type: 'button', class: 'diagnose', 'data-batch': String(b),
              onclick: () => runDiagnosis(runs.map((r) => r.id), out), text: 'diagnose'})),
            el('td', {}, el('a', {href: '#/compare?runs=' + runs.slice(0, 12).map((r) => r.id).join(','), text: 'overlay'})));
        })));
  } catch (e) { showError(e, box); }
}

// ---- start
document.addEventListener('DOMContentLoaded', async () => {
  $('#login').addEventListener('submit', async (ev) => {
    ev.preventDefault();
    const t = $('#token').value.trim();
    if (!t) return;
    $('#token').value = '';
    if (await login(t)) route();
  });
  $('#logout').addEventListener('click', async () => {
    try { await api('POST', '/api/logout'); } catch (e) { /* the cookie goes anyway with the session */ }
    sessionStorage.removeItem(TOKEN_KEY);
    showLoggedOut();
    route();
  });
  window.addEventListener('hashchange', route);
  startConnectionProbe();
  if (token() && !(await login(token()))) return;
  route();
});
