// valvebench web dashboard (docs/web.md). A page of hash routes over the server's /api gateway, which is the
// BenchService itself: this file holds no rule (validation, roles, limits are the server's answers).
'use strict';

const TOKEN_KEY = 'valvebench.token';
const $ = (sel, root) => (root || document).querySelector(sel);
let cleanups = [];  // run when the route changes: timers, EventSources, charts

// An element with attributes (on* = listeners, text = its text) and children: charts.js's, one copy for the
// page and the report.
const el = VBCharts.el;

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
// A run's status, and while its result waits in its host's spool for the store (issue 39: the run is not stuck,
// its result lands when the store takes it) since when.
function runStatusCell(r) {
  const cell = statusCell(r.status);
  if (!r.result_waiting_since_unix_s || r.status !== 'RUNNING') return cell;
  return el('span', {class: 'result-waiting'}, cell, ', result waiting for the store since ', when(r.result_waiting_since_unix_s));
}
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
// Whether the browser's session cookie is live on the server and stands for this tab's token (another tab may
// have logged in as someone else since: the cookie is the browser's, the token the tab's).
async function cookieSessionLive() {
  try {
    const [cookie, tab] = await Promise.all([api('GET', '/api/login'), api('GET', '/api/session')]);
    return cookie.session === true && cookie.user === tab.user;
  } catch (e) { return false; }
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
  [/^\/health$/, pageHealth],
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
  const charts = el('div', {class: 'charts'});
  box.append(el('div', {class: 'actions'}, 'status ', status, ' · ', counter), charts);
  const rowsI = [], rowsX = [], rowsG = [];
  // The run page's charts (charts.js): SI-prefixed axes, the gate as a logic level, one time axis.
  VBFormat.load((p) => api('GET', p)).catch(() => {});
  const C = VBCharts.PALETTE;
  const cI = VBCharts.plot(charts, {title: 'Coil current (live)', class: 'live-current', x: {label: 't', unit: 's'},
    y: {label: 'i', unit: 'A'}, series: [{name: 'i (measured)', color: C[0]}, {name: 'reference', color: C[1]}], rows: [],
    height: 170}, cleanups);
  const cX = VBCharts.plot(charts, {title: 'Spool position (live)', class: 'live-position', x: {label: 't', unit: 's'},
    y: {label: 'x', unit: 'm'}, series: [{name: 'x (measured)', color: C[2]}], rows: [], height: 150}, cleanups);
  // The gate as its duty over each streamed interval (the server's mean of the gate there): a 20 kHz PWM thinned
  // to 200 Hz would otherwise show whichever level each kept instant saw (solid "on" at a high duty).
  const cG = VBCharts.plot(charts, {title: 'Gate duty (live, mean over each interval)', class: 'live-gate',
    x: {label: 't', unit: 's'}, y: {label: 'duty', unit: ''}, series: [{name: 'duty', color: C[3]}], rows: [],
    height: 90}, cleanups);
  let dirty = false, n = 0, lastT = -Infinity, dropped = 0;
  const holes = VBCharts.holes();  // gaps in the stream, drawn as holes (charts.js)
  const timer = setInterval(() => {
    if (!dirty || !cI.g) return;
    dirty = false;
    const span = [rowsI[0][0], rowsI[rowsI.length - 1][0]];
    const range = span[1] > span[0] ? span : null;  // one time range for the three
    cI.rows = rowsI; cX.rows = rowsX; cG.rows = rowsG;
    // Never narrower than 1 mA, 1 µm or 2 % of the largest magnitude (VBCharts.minSpanRange).
    cI.g.updateOptions({file: rowsI, dateWindow: range, valueRange: VBCharts.minSpanRange(rowsI, 1e-3)});
    cX.g.updateOptions({file: rowsX, dateWindow: range, valueRange: VBCharts.minSpanRange(rowsX, 1e-6)});
    cG.g.updateOptions({file: rowsG, dateWindow: range, valueRange: [-0.05, 1.05]});
  }, 250);
  const es = new EventSource('/api/runs/' + runId + '/events?rate_Hz=200');
  const MAX = 20000;
  es.addEventListener('run', (ev) => {
    const e = JSON.parse(ev.data);
    status.replaceChildren(statusCell(e.status), ' ', el('span', {class: 'progress', text: Math.round(100 * (e.progress || 0)) + ' %'}));
    for (const s of e.samples || []) {
      // The server writes fields at zero too (proto3 JSON would leave them out: t_s = 0, x_m = 0 at rest); a
      // missing one is still read as 0, and NaN (no reference) arrives as "NaN".
      const t = typeof s.t_s === 'number' ? s.t_s : 0;
      if (!(t > lastT)) continue;  // a reconnected stream starts over from the run's buffer
      // A hole in the stream is drawn as a hole, never bridged by a line: a row of nulls breaks the three lines.
      const hole = holes.step(t);
      if (hole !== null) { rowsI.push([hole, null, null]); rowsX.push([hole, null]); rowsG.push([hole, null]); }
      lastT = t;
      rowsI.push([t, s.i_A === undefined ? 0 : num(s.i_A), s.ref === undefined ? 0 : num(s.ref)]);
      rowsX.push([t, s.x_m === undefined ? 0 : num(s.x_m)]);
      // A server older than the duty field sends none: the gate level then stands for it.
      rowsG.push([t, s.duty === undefined ? num(s.gate || 0) : num(s.duty)]);
      n++;
    }
    if (rowsI.length > MAX) { for (const r of [rowsI, rowsX, rowsG]) r.splice(0, r.length - MAX); }
    // The server's own count of what this view lost (int64: a string in protobuf JSON).
    dropped = Math.max(dropped, Number(e.dropped_samples || 0));
    counter.textContent = n + ' samples' + (holes.gaps ? ' · ' + holes.gaps + (holes.gaps === 1 ? ' gap' : ' gaps') +
      ' (' + VBFormat.value(holes.missing_s, 's') + ' not received: drawn as holes)' : '') +
      (dropped ? ' · ' + dropped + ' samples dropped by the server (this view fell behind)' : '');
    counter.dataset.samples = String(n);
    counter.dataset.gaps = String(holes.gaps);
    counter.dataset.dropped = String(dropped);
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
// What executing the run measured, as stored with it (Run.execution; docs/decisions.md): its wall and simulated time,
// and, for a paced run, how the loop kept its deadlines. Absent fields (a run that never executed, a loop that was
// not paced) add no row. int64 fields arrive as strings in protobuf JSON.
function executionRows(x) {
  if (!x) return [];
  const rows = [['execution', VBFormat.value(x.simulated_s || 0, 's') + ' simulated, ' + Number(x.samples || 0) +
    ' samples, ' + VBFormat.value(x.wall_s || 0, 's') + ' wall']];
  const l = x.loop;
  if (l) rows.push(['loop', Number(l.ticks || 0) + ' paced ticks, ' + Number(l.overruns || 0) + ' overruns, jitter p50 ' +
    VBFormat.value(l.jitter_p50_s || 0, 's') + ', p99 ' + VBFormat.value(l.jitter_p99_s || 0, 's') + ', max ' +
    VBFormat.value(l.jitter_max_s || 0, 's')]);
  if (x.build) rows.push(['build', String(x.build)]);
  return rows;
}

async function pageRun(main, m) {
  const id = m[1];
  main.replaceChildren(el('h1', {text: 'Run ' + id}), el('p', {class: 'muted', text: 'loading…'}));
  let data;
  try {
    data = await api('GET', '/api/runs/' + id);
    await VBFormat.load((p) => api('GET', p));
  } catch (e) { showError(e, main); return; }
  const r = data.run, units = data.metric_units || {}, cu = data.channel_units || {};
  const ended = !['QUEUED', 'RUNNING'].includes(r.status);
  const actions = el('div', {class: 'actions'},
    ended || !canCancel(r) ? null : el('button', {class: 'danger', id: 'cancel', onclick: () => cancelRun(id, r.submitter).then((ok) => ok && route()), text: 'Cancel'}),
    !canOperate() ? null : (r.tags || []).includes('imported')
      ? el('button', {id: 'rerun', disabled: true, title: 'an imported run is a measurement (benchctl import): there is no spec to run again', text: 'Re-run'})
      : el('button', {id: 'rerun', onclick: () => rerun(id), text: 'Re-run'}),
    ended ? el('a', {href: '/api/runs/' + id + '/trace.csv', id: 'export-csv', text: 'trace CSV'}) : null,
    ended ? el('a', {href: '/api/runs/' + id + '/trace.h5', id: 'export-h5', text: 'HDF5'}) : null,
    ended ? el('a', {href: '/api/runs/' + id + '/trace.mat', id: 'export-mat', text: 'MAT'}) : null,
    el('a', {href: '/api/runs/' + id, id: 'export-json', text: 'run JSON'}),
    el('a', {href: '#/compare?runs=' + id, text: 'compare'}),
    el('a', {href: '#/runs?batch=' + r.batch_id, text: 'batch ' + r.batch_id}));
  const c = (r.spec && r.spec.conditions) || {};
  const kv = el('div', {class: 'kv'});
  for (const [k, v] of [['name', r.name], ['status', runStatusCell(r)], ['reason', r.reason || '–'],
    ['controller', r.controller], ['bench', r.bench || 'any'], ['submitter', r.submitter],
    ['priority', String(r.priority || 0)], ['tags', (r.tags || []).join(', ') || '–'],
    ['conditions.supply_V', fmt(c.supply_V) + ' V'], ['conditions.supply_pressure_Pa', fmt(c.supply_pressure_Pa || 0) + ' Pa'],
    ['duration_s', fmt(r.spec && r.spec.duration_s) + ' s'], ['submitted', when(r.submitted_unix_s)],
    ['started', when(r.started_unix_s)], ['finished', when(r.finished_unix_s)], ...executionRows(r.execution)])
    kv.append(el('div', {text: k}), el('div', {}, v));
  const history = el('table', {class: 'wide'}, el('tr', {}, ['time', 'status', 'reason'].map((h) => el('th', {text: h}))),
    (r.history || []).map((h) => el('tr', {}, el('td', {}, when(h.at_unix_s)), el('td', {}, statusCell(h.status)),
      el('td', {text: h.reason || ''}))));
  const metricNames = Object.keys(r.metrics || {}).sort();
  const metrics = metricNames.length === 0 ? el('p', {class: 'muted', text: 'No metrics (yet).'}) :
    el('table', {id: 'metrics'}, el('tr', {}, ['metric', 'value'].map((h) => el('th', {text: h}))),
      metricNames.map((k) => el('tr', {}, el('td', {text: k}), el('td', {class: 'num', text: VBFormat.value(r.metrics[k], units[k])}))));
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

// The recorded trace, min/max-decimated by the server to ~4000 rows, one chart per quantity on one time axis
// (same range, same left margin; charts.js); zooming refetches the visible window at full resolution
// (double-click: back to the whole run).
async function traceCharts(id, box, cu) {
  const note = el('p', {class: 'muted', text: 'loading trace…'});
  box.append(note);
  let t;
  try {
    await VBFormat.load((p) => api('GET', p));
    t = await api('GET', '/api/runs/' + id + '/trace?max_points=4000');
  } catch (e) { showError(e, note); return; }
  const col = (name) => t.channels.indexOf(name);
  const C = VBCharts.PALETTE;
  // [title, class, [channel, legend name, colour, step], y label, unit, logic]
  const groups = [
    ['Coil current', 'trace-current', [['i_A', 'i (measured)', C[0]]].concat(cu.ref === 'A' ? [['ref', 'reference', C[1]]] : []), 'i', 'A'],
    ['Spool position', 'trace-position', [['x_m', 'x (measured)', C[2]]].concat(cu.ref === 'm' ? [['ref', 'reference', C[1]]] : []), 'x', 'm'],
    ['Coil voltage', 'trace-voltage', [['v_coil_V', 'v_coil', C[4]]], 'v', 'V'],
    ['Gate (logic level)', 'trace-gate', [['gate', 'gate', C[3], true]], 'gate', '', true],
  ];
  note.textContent = t.total_samples + ' samples at ' + VBFormat.value(1 / t.sample_period_s, 'Hz') +
    (t.decimated ? ' (shown as a min/max envelope; drag to zoom for every sample, double-click to reset)' : '');
  const range = t.rows.length ? [t.rows[0][0], t.rows[t.rows.length - 1][0]] : null;
  const charts = [];
  for (const [title, cls, chans, label, unit, logic] of groups) {
    const present = chans.filter(([n]) => col(n) >= 0);
    if (present.length === 0) continue;
    const pick = (rows) => rows.map((row) => [row[0]].concat(present.map(([n]) => row[col(n) + 1])));
    const c = VBCharts.plot(box, {title, class: 'trace-chart ' + cls, x: {label: 't', unit: 's', range},
      y: {label, unit, logic}, series: present.map(([, name, color, step]) => ({name, color, step: !!step})),
      rows: pick(t.rows), height: logic ? 110 : 220}, cleanups);
    c.pick = pick;
    charts.push(c);
  }
  if (!charts.length) return;
  // One zoom for all (charts.js linkTime), then the window at full resolution.
  let latest = 0;  // a window fetched after a newer zoom (or a reset) is dropped
  charts[0].opts.onZoom = async (lo, hi) => {
    const full = lo <= t.rows[0][0] && hi >= t.rows[t.rows.length - 1][0];
    const mine = ++latest;
    try {
      const w = full ? t : await api('GET', '/api/runs/' + id + '/trace?max_points=4000&t_from_s=' + lo + '&t_to_s=' + hi);
      if (mine !== latest) return;
      for (const o of charts) { o.rows = o.pick(w.rows); o.g.updateOptions({file: o.rows, dateWindow: full ? range : [lo, hi]}); }
    } catch (e) { showError(e); }
  };
  for (const o of charts.slice(1)) o.opts.onZoom = charts[0].opts.onZoom;
  VBCharts.linkTime(charts);
}

// ---- Lab, Runs, Submit, Nights: web/static/lists.js
// ---- Compare: web/static/compare.js
// ---- Diagnosis: web/static/diagnosis.js

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
  // A reload keeps the tab's session when the server still has it (GET /api/login), else logs in again.
  if (token()) {
    if (await cookieSessionLive()) {
      await loadSession();
      showLoggedIn();
    } else if (!(await login(token()))) {
      return;
    }
  }
  route();
});
