// valvebench web dashboard: the Compare page (docs/web.md "Compare"). The table is the CLI's (`benchctl compare`):
// the gateway sends each column's header, unit and scale as experiment::MetricColumnDisplay chose them; rows and
// legend entries link to their runs; the scatter is rank metric against the comparison's effort metric with
// labelled points and the Pareto front; a sweep is drawn as curves (1-D) or a heat map (2-D); the runs' traces
// are overlaid, each case in the colour it has in every chart of the page.
'use strict';

// The case's name without its sweep point (the sweep is in its own columns) and without the part before a '/'
// that every case shares (said once in the section's title, as the CLI's table does).
function compareCaseLabel(key, row, common) {
  const n = (key && key.name) || row.name;
  return common && n.startsWith(common) && n.length > common.length ? n.slice(common.length) : n;
}
function commonCasePrefix(names) {
  if (!names.length) return '';
  const first = names[0].slice(0, names[0].indexOf('/') + 1);
  return first && names.every((n) => n.startsWith(first)) ? first : '';
}

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
  if (!q) { await recentBatches(body); return; }
  try { await VBFormat.load((p) => api('GET', p)); } catch (e) { showError(e, body); return; }
  const palette = new VBCharts.Palette();
  let cmp = null;
  try { cmp = await api('GET', '/api/compare?' + q); } catch (e) {
    // The traces can still be overlaid (measured runs without the metrics a comparison ranks).
    body.append(el('section', {}, el('p', {class: 'error', text: errorText(e)})));
  }
  if (cmp && !(cmp.comparison.rows || []).some((r) => (r.run_ids || []).length)) {
    try { await fillRunIds(cmp, params); } catch (e) { /* rows then link to nothing; the rest still draws */ }
  }
  let ids = [];
  if (params.get('runs')) ids = params.get('runs').split(',').filter((x) => /^\d+$/.test(x));
  else if (cmp) ids = (cmp.comparison.rows || []).flatMap((r) => (r.run_ids || []).map(String));
  if (!ids.length && params.get('batch')) {
    try {
      const l = await api('GET', '/api/runs?page_size=200&batch_id=' + encodeURIComponent(params.get('batch')));
      ids = (l.runs || []).map((r) => String(r.id));
    } catch (e) { showError(e, body); return; }
  }
  if (cmp) {
    const d = cmp.display || {};
    const rows = cmp.comparison.rows || [];
    const keys = d.keys || rows.map((r) => r.key || {name: r.name, sweep: []});
    cmp.common = commonCasePrefix(rows.map((r, k) => (keys[k] && keys[k].name) || r.name));
    cmp.names = rows.map((r, k) => compareCaseLabel(keys[k], r, cmp.common));
    cmp.keys = keys;
    cmp.query = q;
    compareTables(body, cmp, palette);
  }
  const swept = cmp && ((cmp.display || {}).sweep_axes || []).length > 0;
  if (swept && ids.length > 12 && !params.get('runs'))
    body.append(el('section', {id: 'overlays'}, el('h2', {text: 'Overlays'}), el('p', {class: 'muted'},
      'A sweep of ' + ids.length + ' runs: follow a case\'s link in the table, or pick runs on the ',
      el('a', {href: '#/runs?batch=' + params.get('batch'), text: 'Runs page'}), ', to overlay their traces.')));
  else await compareOverlays(body, ids, cmp, palette);
}

// A server before CompareRow.run_ids: each row's runs found by their RunKey (name and sweep point), so that rows
// and legends still link to their runs.
async function fillRunIds(cmp, params) {
  let runs = [];
  if (params.get('batch')) {
    const q = new URLSearchParams({page_size: '1000', batch_id: params.get('batch')});
    let data = await api('GET', '/api/runs?' + q.toString());
    runs = data.runs || [];
    while (data.next_page_token && runs.length < 5000) {
      q.set('page_token', data.next_page_token);
      data = await api('GET', '/api/runs?' + q.toString());
      runs = runs.concat(data.runs || []);
    }
  } else if (params.get('runs')) {
    const ids = params.get('runs').split(',').filter((x) => /^\d+$/.test(x)).slice(0, 60);
    runs = (await Promise.all(ids.map((id) => api('GET', '/api/runs/' + id)))).map((x) => x.run);
  }
  const keyOf = (k) => (k && k.name ? k.name + '|' + (k.sweep || []).map((p) => p.field + '=' + Number(Number(p.value).toPrecision(10))).join('|') : null);
  const byKey = new Map();
  for (const r of runs) {
    const k = keyOf(r.key);
    if (!k) continue;
    if (!byKey.has(k)) byKey.set(k, []);
    byKey.get(k).push(String(r.id));
  }
  const keys = (cmp.display || {}).keys || [];
  (cmp.comparison.rows || []).forEach((r, i) => { r.run_ids = byKey.get(keyOf(keys[i])) || []; });
}

// An empty Compare page: the latest batches, each a link to its comparison.
async function recentBatches(body) {
  const box = el('div', {class: 'scroll'});
  body.append(el('section', {id: 'recent-batches'}, el('h2', {text: 'Recent batches'}), box));
  try {
    const l = await api('GET', '/api/runs?page_size=1000');
    const byBatch = new Map();
    for (const r of l.runs || []) {
      const b = String(r.batch_id);
      if (!byBatch.has(b)) byBatch.set(b, {id: b, runs: 0, done: 0, names: new Set(), last: 0, tags: new Set()});
      const x = byBatch.get(b);
      x.runs++;
      if (r.status === 'DONE') x.done++;
      x.names.add((r.key && r.key.name) || r.name);
      x.last = Math.max(x.last, r.submitted_unix_s || 0);
      for (const t of r.tags || []) x.tags.add(t);
    }
    const batches = Array.from(byBatch.values()).sort((a, b) => Number(b.id) - Number(a.id)).slice(0, 15);
    box.replaceChildren(batches.length === 0 ? el('p', {class: 'muted', text: 'No runs yet: submit a spec first.'}) :
      el('table', {class: 'batches'}, el('tr', {}, ['batch', 'cases', 'runs', 'done', 'submitted', ''].map((t) => el('th', {text: t}))),
        batches.map((b) => {
          const names = Array.from(b.names);
          return el('tr', {}, el('td', {}, el('a', {href: '#/runs?batch=' + b.id, text: b.id})),
            el('td', {text: names.slice(0, 3).join(', ') + (names.length > 3 ? ' … (' + names.length + ')' : '')}),
            el('td', {class: 'num', text: String(b.runs)}), el('td', {class: 'num', text: String(b.done)}),
            el('td', {}, when(b.last)),
            el('td', {}, el('a', {href: '#/compare?batch=' + b.id, class: 'compare-batch', text: 'compare'})));
        })));
  } catch (e) { showError(e, box); }
}

function compareTables(body, cmp, palette) {
  const c = cmp.comparison, d = cmp.display || {}, disp = d.columns || {};
  const rows = c.rows || [];
  const keys = cmp.keys;
  const axes = d.sweep_axes || [];
  const laws = d.laws || {};
  const names = cmp.names;
  // One colour per case (a swept case keeps one colour for all its points); a case per law: the law's colour.
  const lawOf = new Map();
  rows.forEach((r, i) => { if (!lawOf.has(names[i])) lawOf.set(names[i], new Set()); lawOf.get(names[i]).add(r.controller); });
  const perLaw = new Set(rows.map((r) => r.controller)).size === lawOf.size && [...lawOf.values()].every((x) => x.size === 1);
  if (perLaw) for (const [n, ctl] of lawOf) palette.fixLaw(n, [...ctl][0]);
  for (const n of names) palette.colorOf(n);
  const allCols = (c.columns || []).filter((k) => disp[k]);
  const storeKey = 'valvebench.compare.columns.' + (d.default_columns || []).join(',');
  let shown = null;
  try { shown = JSON.parse(sessionStorage.getItem(storeKey) || 'null'); } catch (e) { shown = null; }
  if (!Array.isArray(shown)) shown = (d.default_columns || allCols).slice();
  // A long table (a sweep) scrolls in its own box, its header kept in view.
  const tableBox = el('div', {class: 'scroll' + (rows.length > 25 ? ' table-tall' : '')});
  const chooser = el('details', {class: 'columns-chooser'}, el('summary', {text: 'columns (' + allCols.length + ' metrics)'}),
    allCols.map((k) => el('label', {title: k}, el('input', {type: 'checkbox', value: k, checked: shown.includes(k),
      onchange: (ev) => {
        shown = allCols.filter((x) => (x === ev.target.value ? ev.target.checked : shown.includes(x)));
        sessionStorage.setItem(storeKey, JSON.stringify(shown));
        draw();
      }}), ' ' + disp[k].header)));
  const ranked = rows.some((r) => r.rank > 0);
  const front = rows.some((r) => r.pareto);
  // The law, unless every case is named after it (as the CLI's table).
  const showLaw = !rows.every((r, i) => names[i].toLowerCase().startsWith(String(laws[r.controller] || r.controller).toLowerCase()));
  const draw = () => {
    const cols = allCols.filter((k) => shown.includes(k));
    const head = el('tr', {}, ranked ? el('th', {class: 'num', text: 'rank'}) : null, el('th', {text: 'case'}),
      showLaw ? el('th', {text: 'law'}) : null, el('th', {class: 'num', text: 'runs'}),
      axes.map((a) => el('th', {class: 'num sweep', title: a.field, text: a.header})),
      cols.map((k) => el('th', {class: 'num', title: k, 'data-metric': k, text: disp[k].header})),
      front ? el('th', {text: 'Pareto'}) : null);
    const body_ = rows.map((r, i) => {
      const runIds = (r.run_ids || []).map(String);
      const sweep = (keys[i] && keys[i].sweep) || [];
      return el('tr', {'data-runs': runIds.join(',')},
        ranked ? el('td', {class: 'num', text: r.rank > 0 ? String(r.rank) : '–'}) : null,
        el('td', {}, el('i', {class: 'swatch', style: 'background:' + palette.colorOf(names[i])}),
          runIds.length ? el('a', {href: runIds.length === 1 ? '#/run/' + runIds[0] : '#/compare?runs=' + runIds.join(','),
            text: names[i]}) : names[i], r.failed ? el('span', {class: 'error', text: ' (' + r.failed + ' failed)'}) : null),
        showLaw ? el('td', {text: laws[r.controller] || r.controller}) : null,
        el('td', {class: 'num'}, runIds.length ? runIds.map((id, k) => [k ? ' ' : '', runLink(id)]) : String(r.runs || 0)),
        axes.map((a) => {
          const p = sweep.find((x) => x.field === a.field);
          return el('td', {class: 'num', text: p ? VBFormat.cell({mean: p.value, n: 1}, a) : '–'});
        }),
        cols.map((k) => {
          const st = (r.metrics || {})[k];
          return el('td', {class: 'num', text: VBFormat.cell(st, disp[k])});
        }),
        front ? el('td', {text: r.pareto ? '★' : ''}) : null);
    });
    tableBox.replaceChildren(el('table', {id: 'comparison'}, head, body_));
  };
  draw();
  // Downloads by the CLI's own writers (experiment::ComparisonCsv/Json, SI units, every metric; a missing value
  // is an empty CSV field / JSON null): what `benchctl compare --csv/--json` writes.
  const csv = el('span', {class: 'downloads'}, 'download ',
    el('a', {href: '/api/compare.csv?' + cmp.query, id: 'export-compare-csv', text: 'CSV'}), ' ',
    el('a', {href: '/api/compare.json?' + cmp.query, id: 'export-compare-json', text: 'JSON'}));
  const sweepBox = el('div');
  body.append(sweepBox);
  body.append(el('section', {}, el('h2', {text: 'Metrics' + (cmp.common ? ': ' + cmp.common.slice(0, -1) : '')}),
    el('p', {class: 'muted'}, rows.length + ' cases; ' + (ranked ? 'rank by ' + (disp[c.rank_metric] || {}).header +
      ' (rows within the repeat spread share a rank); ' : '') + (front ? '★ = Pareto-optimal in (' +
      (disp[c.rank_metric] || {}).label + ', ' + (disp[c.effort_metric] || {}).label + '). ' : '') +
      (allCols.length ? 'Values are mean ± spread over repeats; "–" = not measured. ' : 'these runs have no metrics (measured runs are compared by their traces). '), csv),
    allCols.length ? chooser : null, tableBox));
  // A sweep's curves before its long table; a comparison's scatter after its short one.
  if (axes.length) sweepCharts(sweepBox, c, d, keys, names, palette, shown);
  else if (allCols.length) scatterChart(body, c, d, names, palette);
}

// Rank metric against effort: each case a labelled point, the Pareto front joined.
function scatterChart(body, c, d, names, palette) {
  const disp = d.columns || {};
  const dx = disp[c.effort_metric], dy = disp[c.rank_metric];
  const sec = el('section', {id: 'pareto-section'});
  body.append(sec);
  const pts = (c.rows || []).map((r, k) => ({name: names[k], ids: r.run_ids || [],
    x: num(((r.metrics || {})[c.effort_metric] || {}).mean), y: num(((r.metrics || {})[c.rank_metric] || {}).mean),
    pareto: r.pareto})).filter((p) => p.x !== null && p.y !== null);
  if (!dx || !dy || !pts.length) { sec.append(el('p', {class: 'muted', text: 'No case has both ' + c.rank_metric + ' and ' + c.effort_metric + '.'})); return; }
  // x and y in the shown units: the axis is labelled with the column's header.
  const X = (p) => p.x * dx.scale, Y = (p) => p.y * dy.scale;
  const series = pts.map((p) => ({name: p.name, color: palette.colorOf(p.name), points: true, width: 0,
    href: p.ids.length === 1 ? '#/run/' + p.ids[0] : p.ids.length ? '#/compare?runs=' + p.ids.join(',') : null}));
  const front = pts.filter((p) => p.pareto).sort((a, b) => a.x - b.x);
  series.push({name: 'Pareto front', color: '#555', width: 1.5, dash: [6, 3], connect: true});
  const rows = pts.map((p, k) => { const r = new Array(pts.length + 2).fill(null); r[0] = X(p); r[k + 1] = Y(p); return r; });
  for (const p of front) { const r = new Array(pts.length + 2).fill(null); r[0] = X(p); r[pts.length + 1] = Y(p); rows.push(r); }
  rows.sort((a, b) => a[0] - b[0]);
  VBCharts.plot(sec, {title: dy.label + ' vs ' + dx.label + ' (effort: ' + c.effort_metric + ')', class: 'pareto',
    x: {label: dx.header, unit: ''}, y: {label: dy.header, unit: ''}, series, rows, pad: 0.12, height: 320,
    labels: pts.map((p) => ({x: X(p), y: Y(p), text: p.name, color: palette.colorOf(p.name)}))}, cleanups);
  sec.querySelector('.vb-chart').id = 'pareto';
}

// A sweep: for one axis, a metric against it, one curve per case; for two, curves against the first (duty when
// there is one, as seed 000's Figs. 8-9), one per value of the other, and a heat map; more axes: the table only.
function sweepCharts(body, c, d, keys, names, palette, shown) {
  const disp = d.columns || {}, axes = d.sweep_axes;
  const sec = el('section', {id: 'sweep-section'});
  const metrics = (shown.length ? shown : d.default_columns || []).filter((k) => disp[k]);
  if (!metrics.length) return;
  const pick = el('select', {id: 'sweep-metric'}, metrics.map((k) => el('option', {value: k, text: disp[k].header})));
  const charts = el('div');
  sec.append(el('div', {class: 'actions'}, el('h2', {text: 'Sweep', style: 'margin:0'}), 'metric ', pick), charts);
  body.append(sec);
  const rows = c.rows || [];
  const coord = (i, field) => { const p = ((keys[i] || {}).sweep || []).find((x) => x.field === field); return p ? p.value : null; };
  const draw = () => {
    charts.replaceChildren();
    const metric = pick.value, dm = disp[metric];
    const value = (i) => { const st = (rows[i].metrics || {})[metric]; return st && st.n > 0 ? st.mean * dm.scale : null; };
    const groups = [...new Set(names)];
    const grid = el('div', {class: 'chart-grid2'});
    charts.append(grid);
    const indexOf = (gname) => rows.map((r, i) => i).filter((i) => names[i] === gname);
    const axesOf = (idx) => axes.filter((a) => idx.some((i) => coord(i, a.field) !== null));
    // Every case swept along the same one axis (a law per variant): one chart, one curve per case.
    const one = groups.map((g) => axesOf(indexOf(g)));
    if (groups.length > 1 && one.every((m) => m.length === 1 && m[0].field === one[0][0].field)) {
      const ax = one[0][0];
      const xs = [...new Set(rows.map((r, i) => coord(i, ax.field)).filter((x) => x !== null))].sort((a, b) => a - b);
      const data = xs.map((x) => [x * ax.scale].concat(groups.map((g) => {
        const i = indexOf(g).find((j) => coord(j, ax.field) === x);
        return i === undefined ? null : value(i);
      })));
      grid.className = '';
      if (data.every((r) => r.slice(1).every((v) => v === null))) {
        grid.append(el('p', {class: 'muted sweep-none', text: 'No ' + dm.label + ' for these runs; pick another metric above.'}));
        return;
      }
      VBCharts.plot(grid, {title: dm.label + ' vs ' + ax.label + ', one curve per case', class: 'sweep-curve',
        x: {label: ax.header, unit: ''}, y: {label: dm.header, unit: ''}, rows: data, pad: 0.04, height: 320,
        series: groups.map((g) => ({name: g, color: palette.colorOf(g), points: true, width: 1.6}))}, cleanups);
      return;
    }
    for (const gname of groups) {
      const idx = indexOf(gname);
      // This case's axes (variants may sweep different fields): duty on x when it is one of them.
      const mine = axesOf(idx);
      if (mine.length === 0 || mine.length > 2) {
        grid.append(el('p', {class: 'muted', text: gname + ': ' + mine.length + ' sweep axes: see the table.'}));
        continue;
      }
      // A case without this metric (an open-loop sweep has no RMSE: it has no reference) gets a sentence, not an
      // empty chart (issue 37: a night's comparison drew an empty RMSE-vs-duty chart).
      if (idx.every((i) => value(i) === null)) {
        grid.append(el('p', {class: 'muted sweep-none', text: gname + ': no ' + dm.label + ' for these runs; pick another metric above.'}));
        continue;
      }
      const xi = mine.length === 2 && /duty$/.test(mine[1].field) ? 1 : 0;
      const ax = mine[xi], other = mine.length === 2 ? mine[1 - xi] : null;
      const lines = other ? [...new Set(idx.map((i) => coord(i, other.field)))].sort((a, b) => a - b) : [null];
      const series = lines.map((v) => ({name: other ? other.label + ' ' + VBFormat.cell({mean: v, n: 1}, other) + (other.unit ? ' ' + other.unit : '') : gname,
        color: other ? VBCharts.PALETTE[lines.indexOf(v) % VBCharts.PALETTE.length] : palette.colorOf(gname), points: true, width: 1.6}));
      const xs = [...new Set(idx.map((i) => coord(i, ax.field)))].sort((a, b) => a - b);
      const data = xs.map((x) => [x * ax.scale].concat(lines.map((v) => {
        const i = idx.find((j) => coord(j, ax.field) === x && (other ? coord(j, other.field) === v : true));
        return i === undefined ? null : value(i);
      })));
      VBCharts.plot(grid, {title: gname + ': ' + dm.label + ' vs ' + ax.label, class: 'sweep-curve',
        x: {label: ax.header, unit: ''}, y: {label: dm.header, unit: ''}, series, rows: data, pad: 0.04, height: 300}, cleanups);
      if (other && xs.length > 1 && lines.length > 1) {
        VBCharts.heatmap(grid, {title: gname + ': ' + dm.header + ' over ' + ax.label + ' and ' + other.label,
          x: {label: ax.header, values: xs, fmt: (v) => VBFormat.cell({mean: v, n: 1}, ax)},
          y: {label: other.header, values: lines, fmt: (v) => VBFormat.cell({mean: v, n: 1}, other)},
          z: {label: dm.header, fmt: (z) => (z === 0 ? '0' : z.toFixed(dm.decimals)),
            get: (x, y) => { const i = idx.find((j) => coord(j, ax.field) === x && coord(j, other.field) === y); return i === undefined ? null : value(i); }}});
      }
    }
  };
  pick.addEventListener('change', draw);
  draw();
}

// The runs' current, position and tracking error overlaid on one time axis, each run in its case's colour.
async function compareOverlays(body, ids, cmp, palette) {
  const sec = el('section', {id: 'overlays'}, el('h2', {text: 'Overlays on a shared time axis'}));
  body.append(sec);
  if (!ids.length) { sec.append(el('p', {class: 'muted', text: 'No runs to overlay.'})); return; }
  const MAX = 12;
  const shown = ids.slice(0, MAX);
  if (ids.length > shown.length) sec.append(el('p', {class: 'muted', text: 'the first ' + shown.length + ' of ' + ids.length + ' runs'}));
  const note = el('p', {class: 'muted', text: 'loading ' + shown.length + ' traces…'});
  sec.append(note);
  let traces;
  try {
    traces = await Promise.all(shown.map((id) => Promise.all([api('GET', '/api/runs/' + id),
      api('GET', '/api/runs/' + id + '/trace?max_points=2000')])));
  } catch (e) { showError(e, note); return; }
  note.remove();
  // A run's colour: its case's when the comparison has it (a row lists its runs), else its own.
  const caseOf = new Map();
  if (cmp) {
    const keys = (cmp.display || {}).keys || [];
    (cmp.comparison.rows || []).forEach((r, k) => { for (const id of r.run_ids || []) caseOf.set(String(id), cmp.names[k]); });
  }
  // A server without CompareRow.run_ids: a run's case by its key's name (a case of one spec without a sweep).
  const byName = new Map();
  if (cmp) (cmp.comparison.rows || []).forEach((r, k) => { if (!((cmp.keys[k] || {}).sweep || []).length) byName.set((cmp.keys[k] || {}).name, cmp.names[k]); });
  for (const [, [data]] of shown.map((id, k) => [id, traces[k]])) {
    const run = data.run, name = (run.key && run.key.name) || run.name;
    if (!caseOf.has(String(run.id)) && byName.has(name)) caseOf.set(String(run.id), byName.get(name));
  }
  const perCase = new Map();
  for (const id of shown) { const cs = caseOf.get(id); if (cs) perCase.set(cs, (perCase.get(cs) || 0) + 1); }
  const series = shown.map((id, k) => {
    const run = traces[k][0].run, cs = caseOf.get(id);
    const full = (run.key && run.key.name) || run.name;
    const name = '#' + id + ' ' + (cmp && cmp.common && full.startsWith(cmp.common) ? full.slice(cmp.common.length) : full);
    // Repeats of one case share its colour; a sweep's runs (many per case) get one each.
    const color = cs && perCase.get(cs) <= 3 ? palette.colorOf(cs) : palette.colorOf(name);
    return {name, color, dash: cs && perCase.get(cs) <= 3 ? palette.dashOf(cs) : palette.dashOf(name), href: '#/run/' + id, width: 1.2};
  });
  const pickCol = (name) => traces.map(([, t]) => { const j = t.channels.indexOf(name); return j < 0 ? [] : t.rows.map((r) => [r[0], r[j + 1]]); });
  const span = traces.map(([, t]) => t.rows.length ? [t.rows[0][0], t.rows[t.rows.length - 1][0]] : null).filter(Boolean);
  const range = span.length ? [Math.min(...span.map((s) => s[0])), Math.max(...span.map((s) => s[1]))] : null;
  const charts = [];
  const add = (title, cls, data, unit, label) => {
    if (!data.some((s) => s.length)) return;
    charts.push(VBCharts.plot(sec, {title, class: cls, x: {label: 't', unit: 's', range}, y: {label, unit}, series,
      rows: mergeSeries(data), height: 230}, cleanups));
  };
  add('Coil current', 'overlay-current', pickCol('i_A'), 'A', 'i');
  add('Spool position', 'overlay-position', pickCol('x_m'), 'm', 'x');
  const err = traces.map(([run, t]) => {
    const refUnit = (run.channel_units || {}).ref;
    const y = t.channels.indexOf(refUnit === 'm' ? 'x_m' : 'i_A'), ref = t.channels.indexOf('ref');
    if (!refUnit || y < 0 || ref < 0) return [];
    return t.rows.map((r) => [r[0], (r[y + 1] === null || r[ref + 1] === null) ? null : r[y + 1] - r[ref + 1]]);
  });
  const units = new Set(traces.map(([run]) => (run.channel_units || {}).ref).filter(Boolean));
  if (err.some((e) => e.length))
    add('Tracking error (controlled variable − reference)', 'overlay-error', err, units.size === 1 ? [...units][0] : '', 'e');
  const ids_ = {'overlay-current': 1, 'overlay-position': 1, 'overlay-error': 1};
  for (const ch of charts) if (ids_[ch.opts.class]) ch.box.id = ch.opts.class;
  if (charts.length > 1) VBCharts.linkTime(charts);
}
