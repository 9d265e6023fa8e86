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
function when(unix_s) {
  if (!unix_s) return '–';
  return new Date(unix_s * 1000).toISOString().replace('T', ' ').replace(/\.\d+Z$/, ' UTC');
}
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
  const res = await fetch(path, opts);
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
  showLoggedIn();
  flash('');
  return true;
}
function showLoggedIn() { $('#login').hidden = true; $('#session').hidden = false; }
function showLoggedOut() { $('#login').hidden = false; $('#session').hidden = true; }

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
  }, opts || {}));
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
  flash('');
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
  const cG = VBCharts.plot(charts, {title: 'Gate (logic level, live)', class: 'live-gate', x: {label: 't', unit: 's'},
    y: {label: 'gate', unit: '', logic: true}, series: [{name: 'gate', color: C[3], step: true}], rows: [], height: 90}, cleanups);
  let dirty = false, n = 0, lastT = -Infinity;
  const timer = setInterval(() => {
    if (!dirty || !cI.g) return;
    dirty = false;
    const span = [rowsI[0][0], rowsI[rowsI.length - 1][0]];
    const range = span[1] > span[0] ? span : null;  // one time range for the three
    cI.rows = rowsI; cX.rows = rowsX; cG.rows = rowsG;
    cI.g.updateOptions({file: rowsI, dateWindow: range});
    cX.g.updateOptions({file: rowsX, dateWindow: range});
    cG.g.updateOptions({file: rowsG, dateWindow: range});
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
      lastT = t;
      rowsI.push([t, s.i_A === undefined ? 0 : num(s.i_A), s.ref === undefined ? 0 : num(s.ref)]);
      rowsX.push([t, s.x_m === undefined ? 0 : num(s.x_m)]);
      rowsG.push([t, num(s.gate || 0)]);
      n++;
    }
    if (rowsI.length > MAX) { for (const r of [rowsI, rowsX, rowsG]) r.splice(0, r.length - MAX); }
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

async function cancelRun(id) {
  try {
    const r = await api('POST', '/api/runs/' + id + '/cancel', {reason: 'cancelled from the web dashboard'});
    flash('run ' + id + ': ' + r.status, true);
  } catch (e) { showError(e); }
}
async function rerun(id) {
  try {
    const r = await api('POST', '/api/runs/' + id + '/rerun');
    flash('re-run of run ' + id + ' queued as run ' + r.run_ids.join(', ') + ' (batch ' + r.batch_id + ')', true);
    location.hash = '#/run/' + r.run_ids[0];
  } catch (e) { showError(e); }
}

// ---- Lab: benches, queue, live runs
// The interlocks beyond the current limit (0 or absent = off; docs/server.md "safety").
function hz(v) {
  if (!v) return '–';
  return v >= 1e6 ? fmt(v / 1e6) + ' MHz' : v >= 1e3 ? fmt(v / 1e3) + ' kHz' : fmt(v) + ' Hz';
}
function interlocks(b) {
  const out = [];
  if (b.max_duty !== undefined && b.max_duty < 1) out.push('duty ≤ ' + fmt(b.max_duty));
  if (b.max_on_time_s) out.push('on ≤ ' + fmt(b.max_on_time_s) + ' s');
  if (b.max_coil_temp_C) out.push('coil ≤ ' + fmt(b.max_coil_temp_C) + ' °C');
  return out.join(', ') || '–';
}
const MAX_LIVE = 4;
function pageLab(main) {
  const benches = el('div', {class: 'scroll'}), queue = el('div', {class: 'scroll'}), live = el('div');
  main.replaceChildren(el('h1', {text: 'Lab'}),
    el('section', {id: 'benches'}, el('h2', {text: 'Benches'}), benches),
    el('section', {id: 'queue'}, el('h2', {text: 'Queue'}), queue),
    el('section', {id: 'live'}, el('h2', {text: 'Running now'}), live));
  const watching = new Map();
  every(1500, async () => {
    const [b, q] = await Promise.all([api('GET', '/api/benches'), api('GET', '/api/queue')]);
    const runName = new Map(q.running.map((r) => [String(r.run.id), r.run.name]));
    benches.replaceChildren(el('table', {},
      el('tr', {}, ['bench', 'kind', 'model', 'driver', 'state', 'max supply [V]', 'trips at [A]', 'interlocks',
        'max carrier / sample / control rate', 'position'].map((h) => el('th', {text: h}))),
      (b.benches || []).map((x) => el('tr', {},
        el('td', {text: x.name}), el('td', {text: x.kind}), el('td', {text: x.model || '–'}), el('td', {text: x.driver}),
        el('td', {}, x.busy ? ['running ', runLink(x.current_run_id), ' ', runName.get(String(x.current_run_id)) || '']
          : x.fault ? el('span', {class: 'status-FAILED', title: x.fault, text: 'faulted: ' + x.fault.slice(0, 80)})
            : 'idle'),
        el('td', {class: 'num', text: fmt(x.max_supply_V)}), el('td', {class: 'num', text: fmt(x.max_current_A)}),
        el('td', {text: interlocks(x)}),
        el('td', {text: [x.max_carrier_Hz, x.max_sample_rate_Hz, x.max_control_rate_Hz].map(hz).join(' / ')}),
        el('td', {text: x.measures_position ? 'measured' : 'none'})))));
    const rows = [];
    for (const r of q.running) rows.push(['running', r.run, duration(r.eta_s)]);
    for (const r of q.queued) {
      rows.push([String(r.position), r.run, r.eta_s == null ? 'after ' + (r.position - 1 + q.running.length) + ' run(s)'
                                                            : duration(r.eta_s)]);
    }
    queue.replaceChildren(rows.length === 0 ? el('p', {class: 'muted', text: 'Nothing queued or running.'}) :
      el('table', {},
        el('tr', {}, ['position', 'run', 'name', 'status', 'progress', 'ETA', 'bench', 'priority', 'submitter', 'submitted', '']
          .map((h) => el('th', {text: h}))),
        rows.map(([p, r, eta]) => el('tr', {'data-run': r.id},
          el('td', {text: p}), el('td', {}, runLink(r.id)), el('td', {text: r.name}), el('td', {}, statusCell(r.status)),
          el('td', {class: 'num', text: Math.round(100 * (r.progress || 0)) + ' %'}), el('td', {text: eta}),
          el('td', {text: r.bench || 'any'}), el('td', {class: 'num', text: String(r.priority || 0)}),
          el('td', {text: r.submitter}), el('td', {text: when(r.submitted_unix_s)}),
          el('td', {}, el('button', {class: 'danger cancel', onclick: () => cancelRun(r.id), text: 'Cancel'}))))));
    const ids = new Set(q.running.map((r) => String(r.run.id)));
    for (const r of q.running) {
      const id = String(r.run.id);
      if (watching.has(id)) continue;
      // A browser keeps about 6 connections per server over HTTP/1.1, and each live view holds one: at most
      // MAX_LIVE here, the rest are a click away (their run page streams them).
      const open = Array.from(watching.values()).filter((b) => !b.dataset.ended).length;
      if (open >= MAX_LIVE) {
        if (!live.querySelector('p.more')) live.append(el('p', {class: 'muted more', text: 'More runs are running: open them from the queue to watch them live.'}));
        continue;
      }
      const box = el('div', {class: 'live-run', 'data-run': id},
        el('h2', {}, runLink(id, 'Run ' + id), ' ', r.run.name, ' on ', r.run.bench || '?'));
      live.append(box);
      watching.set(id, box);
      liveView(id, box);
    }
    for (const [id, box] of watching) {
      if (ids.has(id) || box.dataset.ended) continue;
      box.dataset.ended = '1';
      box.append(el('p', {class: 'muted', text: 'finished: see the run page'}));
      setTimeout(() => { box.remove(); watching.delete(id); }, 15000);
    }
    if (watching.size === 0 && !live.querySelector('p.muted.none'))
      live.replaceChildren(el('p', {class: 'muted none', text: 'No run is running.'}));
    else if (watching.size > 0) { const p = live.querySelector('p.none'); if (p) p.remove(); }
  });
}

// ---- Runs: a filtered list, selection for comparison
async function pageRuns(main, m, params) {
  const batch = params.get('batch') || '', status = params.get('status') || '', tag = params.get('tag') || '';
  const name = params.get('name') || '';  // a suite case (RunKey.name), e.g. from the Nights page
  const form = el('form', {class: 'actions', onsubmit: (ev) => {
    ev.preventDefault();
    const q = new URLSearchParams();
    for (const k of ['batch', 'status', 'tag', 'name']) { const v = $('#f-' + k).value.trim(); if (v) q.set(k, v); }
    location.hash = '#/runs?' + q.toString();
  }},
  'batch ', el('input', {id: 'f-batch', type: 'text', size: 6, value: batch}),
  ' status ', el('select', {id: 'f-status'}, ['', 'QUEUED', 'RUNNING', 'DONE', 'FAILED', 'CANCELLED', 'INTERRUPTED']
    .map((s) => el('option', {value: s, selected: s === status, text: s || 'any'}))),
  ' tag ', el('input', {id: 'f-tag', type: 'text', size: 12, value: tag}),
  ' case ', el('input', {id: 'f-name', type: 'text', size: 16, value: name}),
  el('button', {type: 'submit', text: 'Filter'}));
  const table = el('div', {class: 'scroll'});
  const compare = el('button', {class: 'primary', id: 'compare-selected', text: 'Compare selected', onclick: () => {
    const ids = Array.from(main.querySelectorAll('input.pick:checked')).map((c) => c.value);
    if (ids.length) location.hash = '#/compare?runs=' + ids.join(',');
  }});
  main.replaceChildren(el('h1', {text: 'Runs'}), el('section', {}, form, el('div', {class: 'actions'}, compare,
    batch ? el('a', {href: '#/compare?batch=' + batch, text: 'compare batch ' + batch}) : null), table));
  const q = new URLSearchParams({page_size: '200'});
  if (batch) q.set('batch_id', batch);
  if (status) q.set('status', status);
  if (tag) q.set('tag', tag);
  try {
    let data = await api('GET', '/api/runs?' + q.toString());
    let runs = data.runs || [];
    while (data.next_page_token && runs.length < 2000) {
      q.set('page_token', data.next_page_token);
      data = await api('GET', '/api/runs?' + q.toString());
      runs = runs.concat(data.runs || []);
    }
    runs.reverse();  // newest first
    if (name) runs = runs.filter((r) => (r.key || {}).name === name);
    table.replaceChildren(runs.length === 0 ? el('p', {class: 'muted', text: 'No runs match.'}) : el('table', {id: 'runs'},
      el('tr', {}, ['', 'run', 'batch', 'name', 'controller', 'status', 'bench', 'submitter', 'submitted', 'rmse', 'effort_l2']
        .map((h) => el('th', {text: h}))),
      runs.map((r) => el('tr', {},
        el('td', {}, el('input', {type: 'checkbox', class: 'pick', value: r.id})),
        el('td', {}, runLink(r.id)), el('td', {}, el('a', {href: '#/runs?batch=' + r.batch_id, text: r.batch_id})),
        el('td', {text: r.name}), el('td', {text: r.controller}), el('td', {}, statusCell(r.status)),
        el('td', {text: r.bench}), el('td', {text: r.submitter}), el('td', {text: when(r.submitted_unix_s)}),
        el('td', {class: 'num', text: fmt((r.metrics || {}).rmse)}),
        el('td', {class: 'num', text: fmt((r.metrics || {}).effort_l2)})))));
  } catch (e) { showError(e, table); }
}

// ---- Run page: spec, conditions, history, metrics with units, traces with zoom, export links, live view
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
    ended ? null : el('button', {class: 'danger', id: 'cancel', onclick: () => cancelRun(id).then(() => route()), text: 'Cancel'}),
    (r.tags || []).includes('imported')
      ? el('button', {id: 'rerun', disabled: true, title: 'an imported run is a measurement (benchctl import): there is no spec to run again', text: 'Re-run'})
      : el('button', {id: 'rerun', onclick: () => rerun(id), text: 'Re-run'}),
    ended ? el('a', {href: '/api/runs/' + id + '/trace.csv', id: 'export-csv', text: 'trace CSV'}) : null,
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
    ['started', when(r.started_unix_s)], ['finished', when(r.finished_unix_s)]]) kv.append(el('div', {text: k}), el('div', {}, v));
  const history = el('table', {}, el('tr', {}, ['time', 'status', 'reason'].map((h) => el('th', {text: h}))),
    (r.history || []).map((h) => el('tr', {}, el('td', {text: when(h.at_unix_s)}), el('td', {}, statusCell(h.status)),
      el('td', {text: h.reason || ''}))));
  const metricNames = Object.keys(r.metrics || {}).sort();
  const metrics = metricNames.length === 0 ? el('p', {class: 'muted', text: 'No metrics (yet).'}) :
    el('table', {id: 'metrics'}, el('tr', {}, ['metric', 'value'].map((h) => el('th', {text: h}))),
      metricNames.map((k) => el('tr', {}, el('td', {text: k}), el('td', {class: 'num', text: VBFormat.value(r.metrics[k], units[k])}))));
  const traces = el('section', {id: 'traces'}, el('h2', {text: 'Traces'}));
  main.replaceChildren(el('h1', {}, 'Run ' + id + ' ', statusCell(r.status)), actions,
    el('div', {class: 'grid2'},
      el('section', {}, el('h2', {text: 'Run'}), kv),
      el('section', {}, el('h2', {text: 'History'}), el('div', {class: 'scroll'}, history),
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

// ---- Submit: a spec as JSON; the server's validation answers (field-named errors)
const EXAMPLE_SPEC = {
  name: 'web-pi-current',
  description: 'PI current control at 0.5 A on seed 000\'s valve, submitted from the web dashboard',
  bench: {model: {preset: 'taghizadeh2009'}, driver: {kind: 'low_side_flyback'}},
  conditions: {supply_V: 24.0, supply_pressure_Pa: 400000.0},
  reference: {on_off_profile: {switching_value: 0.9, switching_time_s: 0.006, holding_value: 0.5}},
  controller: {pi_current: {}},
  duration_s: 0.1,
  metric_window: {start_s: 0.02, end_s: 0.1},
  recording: {rate_Hz: 50000.0},
};
function pageSubmit(main) {
  const text = el('textarea', {id: 'spec', spellcheck: 'false'});
  text.value = sessionStorage.getItem('valvebench.draft') || JSON.stringify(EXAMPLE_SPEC, null, 2);
  const batch = el('input', {id: 'batch-name', type: 'text', size: 30, placeholder: 'batch name (default: the spec name)'});
  const out = el('div', {id: 'submit-result'});
  const submit = async (ev) => {
    ev.preventDefault();
    sessionStorage.setItem('valvebench.draft', text.value);
    let spec;
    try { spec = JSON.parse(text.value); } catch (e) {
      out.replaceChildren(el('p', {class: 'error', text: 'spec: not JSON: ' + e.message})); return;
    }
    const body = {spec};
    if (batch.value.trim()) body.batch_name = batch.value.trim();
    try {
      const r = await api('POST', '/api/runs', body);
      out.replaceChildren(el('p', {class: 'ok'}, 'Queued batch ', el('a', {href: '#/runs?batch=' + r.batch_id, text: r.batch_id}),
        ': runs ', r.run_ids.map((id, k) => [k ? ', ' : '', runLink(id)])));
    } catch (e) { out.replaceChildren(el('p', {class: 'error', text: errorText(e)})); }
  };
  main.replaceChildren(el('h1', {text: 'Submit a spec'}),
    el('section', {}, el('p', {class: 'muted'}, 'An experiment spec as protobuf JSON (docs/spec.md); variants, sweep ' +
      'axes and repeats expand into a batch. The server validates it and names the field it refuses.'),
    el('form', {onsubmit: submit}, text, el('div', {class: 'actions'}, batch,
      el('button', {class: 'primary', id: 'submit', type: 'submit', text: 'Submit'}))), out));
}

// ---- Compare: web/static/compare.js

// ---- Nights: regression history, verdicts, links to the night's runs
async function pageNights(main) {
  const box = el('div', {class: 'scroll'});
  main.replaceChildren(el('h1', {text: 'Nightly regressions'}), el('section', {}, box));
  try {
    const n = await api('GET', '/api/nights?limit=60');
    const nights = n.nights || [];
    box.replaceChildren(nights.length === 0 ? el('p', {class: 'muted', text: 'No night has run yet (config "nights").'}) :
      el('table', {id: 'nights'}, el('tr', {}, ['date', 'verdict', 'regressed', 'unchanged', 'improved', 'suite', 'baseline',
        'started', 'finished', 'runs', 'regressed runs', 'summary'].map((h) => el('th', {text: h}))),
      nights.map((x) => el('tr', {}, el('td', {text: x.date}), el('td', {}, el('span', {class: 'verdict-' + x.verdict, text: x.verdict})),
        el('td', {class: 'num', text: String(x.regressed_count || 0)}), el('td', {class: 'num', text: String(x.unchanged || 0)}),
        el('td', {class: 'num', text: String(x.improved || 0)}), el('td', {text: x.suite || ''}), el('td', {text: x.baseline || ''}),
        el('td', {text: when(x.started_unix_s)}), el('td', {text: when(x.finished_unix_s)}),
        el('td', {}, x.batch_id && x.batch_id !== '0' ? [el('a', {href: '#/runs?batch=' + x.batch_id, text: 'batch ' + x.batch_id}),
          ' ', el('a', {href: '#/runs?batch=' + x.batch_id + '&status=FAILED', text: 'failed'}),
          ' ', el('a', {href: '#/compare?batch=' + x.batch_id, text: 'compare'})] : '–'),
        el('td', {class: 'regressed-cases'}, (x.regressed_cases || []).map((c, k) => [k ? ', ' : '',
          el('a', {href: '#/runs?batch=' + x.batch_id + '&name=' + encodeURIComponent(c), text: c})])),
        el('td', {class: 'wrap', text: x.summary || ''})))));
  } catch (e) { showError(e, box); }
}

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
  if (token() && !(await login(token()))) return;
  route();
});
