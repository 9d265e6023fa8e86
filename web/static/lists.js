// valvebench web dashboard (docs/web.md): the Lab, Runs, Submit (and Import) and Nights pages, the signed-in
// user and role, local times, the "disconnected" banner. Loaded before app.js, which holds the shared helpers
// (el, api, fmt, ...) and the routes: this file only defines functions at load time.
'use strict';

// ---- who is signed in (GET /api/session: the server's own Authenticator). The role only hides what the
// service would refuse anyway; the service still decides.
let me = null;  // {user, role} or null
const ROLE_RANK = {viewer: 0, operator: 1, admin: 2};
function roleAtLeast(role) { return !!me && (ROLE_RANK[me.role] || 0) >= ROLE_RANK[role]; }
function canOperate() { return roleAtLeast('operator'); }
// Operators cancel their own runs, admins anyone's (server/auth.h).
function canCancel(run) { return roleAtLeast('admin') || (canOperate() && run && run.submitter === me.user); }
const VIEWER_REASON = 'needs the operator role (you are a viewer)';

async function loadSession() {
  try { me = await api('GET', '/api/session'); } catch (e) { me = null; }
  const text = $('#session-text');
  if (me) {
    text.replaceChildren(el('span', {class: 'user', text: me.user}), ' ', el('span', {class: 'role role-' + me.role, text: me.role}));
    text.title = 'signed in as ' + me.user + ' (' + me.role + ')';
  } else text.textContent = 'signed in';
  document.body.dataset.role = me ? me.role : '';
}

// ---- time: local, with the zone shown; UTC on hover (the CLI prints local time too).
const ZONE = (() => {
  try {
    const p = new Intl.DateTimeFormat(undefined, {timeZoneName: 'short'}).formatToParts(new Date());
    return (p.find((x) => x.type === 'timeZoneName') || {}).value || '';
  } catch (e) { return ''; }
})();
// Text that may break after _ / . : = (identifiers like hysteresis_current, static-map/fig8 sweep:a.b=0.3):
// narrow tables wrap there instead of mid-word or not at all.
function breakable(text) {
  const out = [];
  for (const part of String(text === undefined || text === null ? '' : text).split(/(?<=[_/.:=,])/)) {
    if (out.length) out.push(el('wbr'));
    out.push(part);
  }
  return el('span', {class: 'breakable'}, out);
}
function pad2(n) { return String(n).padStart(2, '0'); }
function localText(unix_s) {
  const d = new Date(unix_s * 1000);
  return d.getFullYear() + '-' + pad2(d.getMonth() + 1) + '-' + pad2(d.getDate()) + ' ' + pad2(d.getHours()) + ':' +
    pad2(d.getMinutes()) + ':' + pad2(d.getSeconds());
}
function utcText(unix_s) { return new Date(unix_s * 1000).toISOString().replace('T', ' ').replace(/\.\d+Z$/, ' UTC'); }
// A <time> element: local time and zone, UTC in its tooltip.
function timeCell(unix_s) {
  if (!unix_s) return '–';
  const [day, clock] = localText(unix_s).split(' ');
  // Two unbreakable halves: a narrow table puts the date over the time, never the zone alone.
  return el('time', {datetime: new Date(unix_s * 1000).toISOString(), title: utcText(unix_s)},
    el('span', {class: 'nowrap', text: day}), ' ', el('span', {class: 'nowrap', text: clock + (ZONE ? ' ' + ZONE : '')}));
}
function runDuration_s(r) {
  if (!r.started_unix_s) return null;
  const end = r.finished_unix_s || (r.status === 'RUNNING' ? Date.now() / 1000 : null);
  return end ? Math.max(0, end - r.started_unix_s) : null;
}

// ---- connection state: a banner while the server does not answer; it clears when it answers again.
let connectionLost = false;
let keepFlashUntil = 0;  // route() keeps the flash until then (ms): a cancel's result over the re-rendered page
let lastAnswer = 0;  // when the server last answered (ms)
function setConnected(ok, why) {
  const b = $('#disconnected');
  if (!b) return;
  if (!ok) {
    connectionLost = true;
    b.replaceChildren(el('strong', {text: 'Disconnected from the server — retrying.'}), ' ',
      el('span', {class: 'muted', text: 'What the page shows is from ' + (lastAnswer ? localText(lastAnswer / 1000).slice(11) : 'before') +
        ' and may be stale.'}));
    b.title = why || '';
    b.hidden = false;
    document.body.classList.add('stale');
  } else {
    lastAnswer = Date.now();
    if (!connectionLost) return;
    connectionLost = false;
    b.hidden = true;
    document.body.classList.remove('stale');
    afterReconnect();
  }
}
// The server is back after an outage. It keeps its sessions over a restart (web/session_store.h), so the cookie
// that live views and downloads use usually still works: GET /api/login says whether it does. When it does not
// (a server without a sessions file, a session that expired or was ended elsewhere), the page logs in again with
// the token this tab holds (a bearer call) and redraws the current view, whose live streams reopen with the new
// cookie: no reload needed (issue 37, point 4; issue 39, point 4). Views holding the user's unsent input
// (Submit, Import) are not redrawn; their next action goes out with the session.
async function afterReconnect() {
  if (token()) {
    if (!(await cookieSessionLive())) {
      try { await api('POST', '/api/login', {token: token()}); } catch (e) {
        if (e instanceof ApiError && e.status === 401) {  // the token itself is no longer configured
          sessionStorage.removeItem(TOKEN_KEY);
          showLoggedOut();
          flash('The server is back but no longer knows your token: log in again.');
        }
        return;
      }
    }
  }
  if (!/^#\/(submit|import)/.test(location.hash)) route();
}
// Probes the server while the banner shows; a page whose own polling stopped still learns it is back.
function startConnectionProbe() {
  setInterval(async () => {
    if (!connectionLost) return;
    try { await fetch('/api/session', {cache: 'no-store'}); setConnected(true); } catch (e) { /* still away */ }
  }, 2000);
}

// ---- cancel: asks for confirmation and a reason; the result shows in the flash and on the row.
async function cancelRun(id, submitter) {
  const reason = window.prompt('Cancel run ' + id + (submitter ? ' (submitted by ' + submitter + ')' : '') +
    '?\nReason (recorded as "cancelled by you: reason"):', '');
  if (reason === null) return false;  // "Cancel" in the dialog: nothing happens
  try {
    const body = reason.trim() ? {reason: reason.trim()} : {};
    const r = await api('POST', '/api/runs/' + id + '/cancel', body);
    flash('Run ' + id + ' ' + String(r.status).toLowerCase() + (r.reason ? ': ' + r.reason : ''), true);
    keepFlashUntil = Date.now() + 8000;
    return true;
  } catch (e) { showError(e); return false; }
}
function cancelButton(run, after) {
  if (!canCancel(run)) return null;
  return el('button', {class: 'danger cancel', type: 'button', title: 'cancel run ' + run.id,
    onclick: async () => { if (await cancelRun(run.id, run.submitter) && after) after(); }, text: 'Cancel'});
}

// ---- Lab: benches, queue, live runs
function hz(v) {
  if (!v) return '–';
  return v >= 1e6 ? fmt(v / 1e6) + ' MHz' : v >= 1e3 ? fmt(v / 1e3) + ' kHz' : fmt(v) + ' Hz';
}
// The interlocks beyond the current limit (0 or absent = off; docs/server.md "safety").
function interlocks(b) {
  const out = [];
  if (b.max_duty !== undefined && b.max_duty < 1) out.push('duty ≤ ' + fmt(b.max_duty));
  if (b.max_on_time_s) out.push('on ≤ ' + fmt(b.max_on_time_s) + ' s');
  if (b.max_coil_temp_C) out.push('coil ≤ ' + fmt(b.max_coil_temp_C) + ' °C');
  return out.join(', ') || '–';
}
const MAX_LIVE = 4;
function pageLab(main) {
  const benches = el('div', {class: 'fit'}), queue = el('div', {class: 'fit'}), live = el('div');
  main.replaceChildren(el('h1', {text: 'Lab'}),
    el('section', {id: 'benches'}, el('h2', {text: 'Benches'}), benches),
    el('section', {id: 'queue'}, el('h2', {text: 'Queue'}), queue),
    el('section', {id: 'live'}, el('h2', {text: 'Running now'}), live));
  const watching = new Map();
  every(1500, async () => {
    const [b, q] = await Promise.all([api('GET', '/api/benches'), api('GET', '/api/queue')]);
    const runName = new Map(q.running.map((r) => [String(r.run.id), r.run.name]));
    benches.replaceChildren(el('table', {class: 'wide'},
      el('tr', {}, ['bench', 'kind', 'model', 'driver', 'state', 'max supply', 'trips at', 'interlocks',
        'rates: carrier / sample / control', 'position'].map((h) => el('th', {text: h}))),
      (b.benches || []).map((x) => el('tr', {},
        el('td', {text: x.name}), el('td', {text: x.kind}), el('td', {}, breakable(x.model || '–')), el('td', {}, breakable(x.driver)),
        el('td', {class: 'long'}, x.busy ? ['running ', runLink(x.current_run_id), ' ', runName.get(String(x.current_run_id)) || '']
          : x.fault ? el('span', {class: 'status-FAILED', title: x.fault, text: 'faulted: ' + x.fault.slice(0, 80)})
            : 'idle'),
        el('td', {class: 'num', text: fmt(x.max_supply_V) + ' V'}), el('td', {class: 'num', text: fmt(x.max_current_A) + ' A'}),
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
      el('table', {class: 'wide'},
        el('tr', {}, ['position', 'run', 'name', 'status', 'progress', 'ETA', 'bench', 'priority', 'submitter', 'submitted', '']
          .map((h) => el('th', {text: h}))),
        rows.map(([p, r, eta]) => el('tr', {'data-run': r.id},
          el('td', {text: p}), el('td', {}, runLink(r.id)), el('td', {}, breakable(r.name)), el('td', {}, runStatusCell(r)),
          el('td', {class: 'num', text: Math.round(100 * (r.progress || 0)) + ' %'}), el('td', {text: eta}),
          el('td', {text: r.bench || 'any'}), el('td', {class: 'num', text: String(r.priority || 0)}),
          el('td', {text: r.submitter}), el('td', {}, timeCell(r.submitted_unix_s)),
          el('td', {}, cancelButton(r))))));
    const ids = new Set(q.running.map((r) => String(r.run.id)));
    for (const r of q.running) {
      const id = String(r.run.id);
      if (watching.has(id)) continue;
      // A browser keeps about 6 connections per server over HTTP/1.1, and each live view holds one: at most
      // MAX_LIVE here, the rest are a click away (their run page streams them).
      const open = Array.from(watching.values()).filter((x) => !x.dataset.ended).length;
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

// ---- Runs: filters, sorting and paging by the service (ListRuns name/order_by/page_token/total_size)
const RUN_FILTERS = ['batch', 'status', 'tag', 'name', 'bench', 'controller', 'submitter', 'from', 'to'];
const PAGE_SIZES = [25, 50, 100, 200, 500];
// Columns: [header, order_by field or null, cell]. The service sorts (AIP-132 "FIELD" or "FIELD desc").
const RUN_COLUMNS = [
  ['run', 'id', (r) => runLink(r.id)],
  ['batch', null, (r) => el('a', {href: '#/runs?batch=' + r.batch_id, text: r.batch_id})],
  ['name', 'name', (r) => breakable(r.name)],
  ['controller', 'controller', (r) => breakable(r.controller)],
  ['status', 'status', (r) => runStatusCell(r)],
  ['bench', 'bench', (r) => r.bench || '–'],
  ['submitter', 'submitter', (r) => r.submitter],
  ['submitted', 'submitted', (r) => timeCell(r.submitted_unix_s)],
  ['duration', 'duration', (r) => { const d = runDuration_s(r); return d !== null && d < 1 ? fmt(d, 2) + ' s' : duration(d); }],
  ['RMSE', null, (r) => headlineCell(r, 'rank')],
  ['effort', null, (r) => headlineCell(r, 'effort')],
];
// Each law's headline metrics as its comparison shows them (the gateway's `headline`, from the CLI's own
// choice: driver loss for current laws, ||u||2 for position laws), in SI-prefixed units.
let runHeadline = {};
function headlineCell(r, which) {
  const h = (runHeadline[r.controller] || {})[which];
  const v = h ? (r.metrics || {})[h.metric] : undefined;
  if (!h || v === undefined) return '–';
  return el('span', {title: h.metric + (which === 'effort' ? ': the effort metric its comparison ranks against' : ''),
    text: VBFormat.value(v, h.unit) + (which === 'effort' ? ' (' + h.label + ')' : '')});
}
// Page tokens are opaque and forward-only: the tokens of the pages seen so far, per filter and order.
const pageTokens = {key: '', tokens: ['']};
function dayStart_s(date, endOfDay) {  // a <input type=date> value, in local time
  const [y, m, d] = date.split('-').map(Number);
  return new Date(y, m - 1, d + (endOfDay ? 1 : 0)).getTime() / 1000;
}

async function pageRuns(main, m, params) {
  const f = {};
  for (const k of RUN_FILTERS) f[k] = params.get(k) || '';
  const order = params.get('order') || 'submitted desc';
  const size = PAGE_SIZES.includes(Number(params.get('size'))) ? Number(params.get('size')) : 100;
  let page = Math.max(0, parseInt(params.get('page') || '0', 10) || 0);
  const go = (changes) => {
    const q = new URLSearchParams();
    const all = Object.assign({}, f, {order: order === 'submitted desc' ? '' : order, size: size === 100 ? '' : size, page: ''}, changes);
    for (const [k, v] of Object.entries(all)) if (v !== '' && v !== undefined && v !== null && v !== 0) q.set(k, v);
    location.hash = '#/runs' + (q.toString() ? '?' + q.toString() : '');
  };
  const input = (k, attrs) => el('input', Object.assign({id: 'f-' + k, name: k, type: 'text', value: f[k]}, attrs || {}));
  const labelled = (text, control) => el('label', {class: 'filter'}, el('span', {text}), control);
  const form = el('form', {class: 'filters', onsubmit: (ev) => {
    ev.preventDefault();
    const c = {};
    for (const k of RUN_FILTERS) c[k] = $('#f-' + k).value.trim();
    go(c);
  }},
  labelled('batch', input('batch', {size: 6, inputmode: 'numeric'})),
  labelled('status', el('select', {id: 'f-status'}, ['', 'QUEUED', 'RUNNING', 'DONE', 'FAILED', 'CANCELLED', 'INTERRUPTED']
    .map((s) => el('option', {value: s, selected: s === f.status, text: s || 'any'})))),
  labelled('name contains', input('name', {size: 16})),
  labelled('tag', input('tag', {size: 10})),
  labelled('bench', input('bench', {size: 8})),
  labelled('controller', input('controller', {size: 10})),
  labelled('submitter', input('submitter', {size: 8})),
  labelled('submitted from', input('from', {type: 'date'})),
  labelled('to', input('to', {type: 'date'})),
  el('button', {type: 'submit', text: 'Filter'}),
  el('button', {type: 'button', text: 'Clear', onclick: () => { location.hash = '#/runs'; }}));
  const table = el('div', {class: 'fit'});
  const pager = el('div', {class: 'pager actions'});
  const compare = el('button', {class: 'primary', id: 'compare-selected', text: 'Compare selected', onclick: () => {
    const ids = Array.from(main.querySelectorAll('input.pick:checked')).map((c) => c.value);
    if (ids.length) location.hash = '#/compare?runs=' + ids.join(',');
  }});
  main.replaceChildren(el('h1', {text: 'Runs'}), el('section', {}, form, el('div', {class: 'actions'}, compare,
    f.batch ? el('a', {href: '#/compare?batch=' + f.batch, text: 'compare batch ' + f.batch}) : null,
    f.batch ? el('a', {href: '/api/batches/' + encodeURIComponent(f.batch) + '/report.html', id: 'batch-report', target: '_blank',
      text: 'HTML report of batch ' + f.batch}) : null), pager, table));

  const q = new URLSearchParams({page_size: String(size), order_by: order});
  if (f.batch) q.set('batch_id', f.batch);
  for (const k of ['status', 'tag', 'name', 'bench', 'controller', 'submitter']) if (f[k]) q.set(k, f[k]);
  if (f.from) q.set('submitted_after_unix_s', String(dayStart_s(f.from, false)));
  if (f.to) q.set('submitted_before_unix_s', String(dayStart_s(f.to, true)));
  const key = q.toString();
  if (pageTokens.key !== key) { pageTokens.key = key; pageTokens.tokens = ['']; }
  if (page >= pageTokens.tokens.length) page = 0;  // a reloaded page N: its token is gone, start over
  if (pageTokens.tokens[page]) q.set('page_token', pageTokens.tokens[page]);
  let data;
  try {
    await VBFormat.load((p) => api('GET', p));
    data = await api('GET', '/api/runs?' + q.toString());
  } catch (e) { showError(e, table); return; }
  runHeadline = data.headline || {};
  let runs = data.runs || [];
  // A server before ListRuns' name filter (api.proto field 11) answers every run: keep the matching ones.
  if (f.name) runs = runs.filter((r) => (r.name || '').includes(f.name) || (r.key || {}).name === f.name);
  if (data.next_page_token) pageTokens.tokens[page + 1] = data.next_page_token;
  const total = data.total_size === undefined ? null : Number(data.total_size);
  const first = page * size + 1, last = page * size + runs.length;
  pager.replaceChildren(
    el('button', {type: 'button', id: 'page-prev', disabled: page === 0, onclick: () => go({page: page - 1}), text: '‹ Previous'}),
    el('span', {id: 'page-info', text: runs.length === 0 ? 'no runs' :
      'showing ' + first + '–' + last + ' of ' + (total !== null ? total : last + (data.next_page_token ? '+' : ''))}),
    el('button', {type: 'button', id: 'page-next', disabled: !data.next_page_token, onclick: () => go({page: page + 1}), text: 'Next ›'}),
    el('label', {class: 'filter'}, el('span', {text: 'per page'}), el('select', {id: 'page-size',
      onchange: (ev) => go({size: Number(ev.target.value)})},
    PAGE_SIZES.map((n) => el('option', {value: n, selected: n === size, text: String(n)})))));
  const [orderField, orderDir] = order.split(/\s+/);
  const header = el('tr', {}, el('th', {text: ''}), RUN_COLUMNS.map(([h, field]) => {
    if (!field) return el('th', h === 'effort' ? {text: h, title: 'each law\'s effort metric, as its comparison ranks it (hover a value for its name)'} : {text: h});
    const active = field === orderField, desc = active && orderDir === 'desc';
    // A click sorts by the column; a second click reverses it. Times and ids start newest first.
    const next = active ? (desc ? field : field + ' desc') : (['id', 'submitted', 'duration'].includes(field) ? field + ' desc' : field);
    return el('th', {class: 'sortable' + (active ? ' sorted' : ''), 'data-order': field, 'aria-sort': active ? (desc ? 'descending' : 'ascending') : 'none'},
      el('a', {href: '#', title: 'sort by ' + h, onclick: (ev) => { ev.preventDefault(); go({order: next}); }},
        h, active ? (desc ? ' ▼' : ' ▲') : ''));
  }));
  table.replaceChildren(runs.length === 0 ? el('p', {class: 'muted', text: 'No runs match.'}) : el('table', {id: 'runs', class: 'wide'},
    header, runs.map((r) => el('tr', {'data-run': r.id},
      el('td', {}, el('input', {type: 'checkbox', class: 'pick', value: r.id, 'aria-label': 'pick run ' + r.id})),
      RUN_COLUMNS.map(([h, , cell]) => el('td', {class: ['RMSE', 'effort', 'duration'].includes(h) ? 'num' : undefined}, cell(r)))))));
}

// ---- Submit (operator): a spec as JSON; the server's validation answers (field-named errors). Import: a
// dataset's files (docs/dataset-format.md) uploaded as ImportRuns.
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
  const allowed = canOperate();
  const submit = async (ev) => {
    ev.preventDefault();
    if (!allowed) return;
    sessionStorage.setItem('valvebench.draft', text.value);
    let spec;
    try { spec = JSON.parse(text.value); } catch (e) {
      out.replaceChildren(el('p', {class: 'error', text: 'spec: not JSON: ' + e.message})); return;
    }
    const body = {spec};
    if (batch.value.trim()) body.batch_name = batch.value.trim();
    try {
      const r = await api('POST', '/api/runs', body);
      // A sweep can queue hundreds of runs: their count, the first few, and where to follow the batch as a whole.
      const ids = r.run_ids || [], SHOWN = 8;
      out.replaceChildren(el('p', {class: 'ok', id: 'submitted'}, 'Queued batch ', el('a', {href: '#/runs?batch=' + r.batch_id, text: r.batch_id}),
        ': ' + ids.length + (ids.length === 1 ? ' run (' : ' runs ('), ids.slice(0, SHOWN).map((id, k) => [k ? ', ' : '', runLink(id)]),
        ids.length > SHOWN ? ', … ' + (ids.length - SHOWN) + ' more' : '', ') · ',
        el('a', {href: '#/runs?batch=' + r.batch_id, text: 'follow the batch'}), ' · ',
        el('a', {href: '#/compare?batch=' + r.batch_id, id: 'compare-submitted', text: 'compare this batch'})));
    } catch (e) { out.replaceChildren(el('p', {class: 'error', text: errorText(e)})); }
  };
  main.replaceChildren(el('h1', {text: 'Submit a spec'}),
    // replaceChildren writes a null child as the text "null": leave the notice out instead.
    ...(allowed ? [] : [el('p', {class: 'notice', id: 'role-notice', text: 'You can read this page, but submitting ' + VIEWER_REASON + '.'})]),
    el('section', {}, el('p', {class: 'muted'}, 'An experiment spec as protobuf JSON (docs/spec.md); variants, sweep ' +
      'axes and repeats expand into a batch. The server validates it and names the field it refuses.'),
    el('form', {onsubmit: submit}, text, el('div', {class: 'actions'}, batch,
      allowed ? el('button', {class: 'primary', id: 'submit', type: 'submit', text: 'Submit'})
        : el('button', {class: 'primary', id: 'submit', type: 'submit', disabled: true, title: 'Submit ' + VIEWER_REASON, text: 'Submit'}))), out),
    importSection(allowed));
}

// Import: a measured dataset's manifest.json and files (docs/dataset-format.md), read in the browser and sent
// as JSON to /api/import, which reads them as `benchctl import DIR` does and stores them with ImportRuns.
function importSection(allowed) {
  const files = el('input', {id: 'import-files', type: 'file', multiple: true, accept: '.json,.csv,application/json,text/csv'});
  const name = el('input', {id: 'import-name', type: 'text', size: 20, placeholder: 'dataset name', pattern: '[A-Za-z0-9][A-Za-z0-9._\\-]*'});
  const out = el('div', {id: 'import-result'});
  const submit = async (ev) => {
    ev.preventDefault();
    if (!allowed) return;
    const picked = Array.from(files.files || []);
    if (picked.length === 0) { out.replaceChildren(el('p', {class: 'error', text: 'files: pick manifest.json and its CSV files'})); return; }
    const body = {dataset: name.value.trim(), files: {}};
    for (const f of picked) body.files[f.name] = await f.text();
    out.replaceChildren(el('p', {class: 'muted', text: 'importing ' + picked.length + ' files…'}));
    try {
      const r = await api('POST', '/api/import', body);
      out.replaceChildren(el('p', {class: 'ok'}, 'Imported ', String((r.run_ids || []).length), ' runs as batch ',
        el('a', {href: '#/runs?batch=' + r.batch_id, text: r.batch_id}), ' · ', el('a', {href: '#/diagnosis', text: 'diagnose them'})),
      (r.warnings || []).length ? el('ul', {class: 'muted'}, r.warnings.map((w) => el('li', {text: w}))) : null);
    } catch (e) { out.replaceChildren(el('p', {class: 'error', text: errorText(e)})); }
  };
  return el('section', {id: 'import'}, el('h2', {text: 'Import a measured dataset'}),
    el('p', {class: 'muted', text: 'A dataset of measured runs (valve-runs/1 or /2, docs/dataset-format.md): pick its manifest.json and ' +
      'every file it names (up to 8 MiB in all; larger: benchctl import DIR). The runs are stored for the diagnosis.'}),
    el('form', {class: 'actions', onsubmit: submit}, files, name,
      el('button', {type: 'submit', id: 'import-button', disabled: !allowed, title: allowed ? undefined : 'Import ' + VIEWER_REASON, text: 'Import'})),
    out);
}

// ---- Nights: the next night, regression history, verdicts, links to the night's runs
async function pageNights(main) {
  const box = el('div', {class: 'fit'});
  const next = el('p', {id: 'next-night'});
  main.replaceChildren(el('h1', {text: 'Nightly regressions'}), el('section', {}, next, box));
  try {
    const n = await api('GET', '/api/nights?limit=60');
    const nights = n.nights || [];
    next.replaceChildren(...(n.next_night_unix_s ? ['Next night: ', timeCell(n.next_night_unix_s),
      el('span', {class: 'muted', text: ' (in ' + duration(n.next_night_unix_s - Date.now() / 1000) + ')'})]
      : [el('span', {class: 'muted', text: 'No night scheduled (config "nights").'})]));
    box.replaceChildren(nights.length === 0 ? el('p', {class: 'muted', text: 'No night has run yet (config "nights").'}) :
      el('table', {id: 'nights', class: 'wide'}, el('tr', {}, ['date', 'verdict', 'regressed / unchanged / improved', 'suite', 'baseline',
        'started', 'finished', 'runs', 'regressed cases', 'summary', 'valve and cause'].map((h) => el('th', {text: h}))),
      nights.map((x) => el('tr', {}, el('td', {class: 'nowrap', text: x.date}),
        el('td', {}, el('span', {class: 'verdict-' + x.verdict, text: x.verdict})),
        el('td', {class: 'num', text: (x.regressed_count || 0) + ' / ' + (x.unchanged || 0) + ' / ' + (x.improved || 0)}),
        el('td', {}, breakable(x.suite || '')), el('td', {}, breakable(x.baseline || '')),
        el('td', {}, timeCell(x.started_unix_s)), el('td', {}, timeCell(x.finished_unix_s)),
        el('td', {}, x.batch_id && x.batch_id !== '0' ? [el('a', {href: '#/runs?batch=' + x.batch_id, text: 'batch ' + x.batch_id}),
          ' ', el('a', {href: '#/runs?batch=' + x.batch_id + '&status=FAILED', text: 'failed'}),
          ' ', el('a', {href: '#/compare?batch=' + x.batch_id, text: 'compare'}),
          ' ', el('a', {href: '/api/batches/' + x.batch_id + '/report.html', target: '_blank', text: 'report'})] : '–'),
        el('td', {class: 'regressed-cases'}, (x.regressed_cases || []).map((c, k) => [k ? ', ' : '',
          el('a', {href: '#/runs?batch=' + x.batch_id + '&name=' + encodeURIComponent(c)}, breakable(c))])),
        el('td', {class: 'summary long', text: x.summary || ''}),
        // The bench twin (docs/track.md "On the server"): the valve changes flagged by this night, and why a
        // regressed night regressed (the valve, the code, or undetermined with the reason).
        el('td', {class: 'valve-cause long'}, (x.valve_changes || []).map((v) => el('div', {text: 'valve changed: ' + v}))
          .concat(x.cause ? [el('div', {class: 'cause-' + x.cause, text: 'cause: ' + x.cause + (x.cause_reason ? ' (' + x.cause_reason + ')' : '')})] : []))))));
  } catch (e) { showError(e, box); }
}

// ---- charts in the page's theme: dygraphs draws axes and grid on a canvas, which CSS cannot reach; their
// colours come from the theme's variables (theme.css), read when a chart is made.
function chartTheme() {
  const css = getComputedStyle(document.documentElement);
  const v = (name, fallback) => (css.getPropertyValue(name) || '').trim() || fallback;
  // dygraphs' own series colours (HSV around the wheel) at the theme's value: brighter on a dark page.
  return {axisLineColor: v('--chart-axis', '#555'), gridLineColor: v('--chart-grid', '#ddd'),
    colorValue: Number(v('--chart-color-value', '0.5')), colorSaturation: Number(v('--chart-color-saturation', '1'))};
}
