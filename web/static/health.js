// valvebench web dashboard: the Bench health page (docs/web.md "Bench health", docs/track.md "On the server").
// Each bench's valve as its nightly health checks identify it (GetBenchHealth): per tracked parameter its value
// night by night with the identification's 1-sigma, the reference's mean and its -+3 sigma limits, the night the
// CUSUM flagged it and the night the change started; the fit of each night against its noise floor; the flags
// with what moves each parameter; and the tracking as `benchctl health` prints it.
'use strict';

// A double of protobuf JSON: NaN and the infinities come as strings, absent fields (zeros) not at all.
function healthNum(x) {
  if (x === undefined || x === null || x === 'NaN' || x === 'Infinity' || x === '-Infinity') return null;
  const v = Number(x);
  return Number.isFinite(v) ? v : null;
}

function healthSlug(name) { return String(name).replace(/[^A-Za-z0-9_-]+/g, '-'); }

async function pageHealth(main, m, params) {
  const only = params.get('bench') || '';
  const box = el('div');
  main.replaceChildren(el('h1', {text: 'Bench health'}),
    el('p', {class: 'muted', text: 'Each checked bench\'s valve, identified from its nightly health check (a switch-on run per ' +
      'supply and pressure before the suite, and a PWM hold that measures R_hold and L_hold without a model of the ' +
      'valve, then its drop-out, i_dropout: the current at which the plunger lets go; a bench\'s "health" block). ' +
      'Per parameter: its value each night with the ' +
      'identification\'s 1-sigma, the reference\'s mean and its limits (mean -+ 3 sigma), and the night a self-starting ' +
      'two-sided CUSUM flagged it. A failed night names the valve or the code as its cause on the Nights page.'}), box);
  try {
    await VBFormat.load((p) => api('GET', p));
    const d = await api('GET', '/api/health' + (only ? '?bench=' + encodeURIComponent(only) : ''));
    const benches = d.benches || [];
    if (!benches.length) {
      box.replaceChildren(el('p', {class: 'muted', id: 'health-none',
        text: 'No health check is stored yet: give a bench a "health" block in the server\'s config; its first check runs with the next night.'}));
      return;
    }
    const pick = benches.length > 1 || only ? el('p', {class: 'actions', id: 'health-benches'}, 'bench: ',
      el('a', {href: '#/health', class: only ? '' : 'active', text: 'all'}),
      benches.map((b) => [' ', el('a', {href: '#/health?bench=' + encodeURIComponent(b.bench), class: b.bench === only ? 'active' : '', text: b.bench})])) : null;
    box.replaceChildren(...(pick ? [pick] : []));
    for (const b of benches) benchHealthSection(b, box);  // attached first: a chart draws only on the page
  } catch (e) { showError(e, box); }
}

function benchHealthSection(b, parent) {
  const nights = b.nights || [];
  const flags = b.flags || [];
  const sec = el('section', {class: 'bench-health', id: 'health-' + healthSlug(b.bench)});
  parent.append(sec);
  const span = nights.length ? nights[0] + ' to ' + nights[nights.length - 1] : '';
  sec.append(el('h2', {text: b.bench}), el('p', {class: 'muted', text: nights.length + ' night' + (nights.length === 1 ? '' : 's') +
    ' identified' + (span ? ' (' + span + ')' : '') + (b.h_sigma ? '; CUSUM k ' + healthNum(b.k_sigma) + ' sigma, h ' +
    healthNum(b.h_sigma).toFixed(2) + ' sigma (in-control run length ' + healthNum(b.target_arl0_nights) + ' nights per parameter)' : '')}));
  // The flags first: what changed, since when, by how much, and what moves it.
  if (flags.length) {
    const params = new Map((b.parameters || []).map((p) => [p.name, p]));
    sec.append(el('table', {class: 'wide health-flags'}, el('tr', {}, ['flagged', 'parameter', 'change', 'z', 'since', 'drift per night', 'what moves it']
      .map((h) => el('th', {text: h}))), flags.map((f) => {
      const unit = (params.get(f.parameter) || {}).unit || f.unit || '';
      const rel = healthNum(f.change_relative), drift = healthNum(f.drift_per_night);
      return el('tr', {class: 'health-flag'}, el('td', {class: 'nowrap', text: f.night}), el('td', {}, el('code', {text: f.parameter})),
        el('td', {class: 'num', text: (f.direction || '') + ' ' + VBFormat.value(healthNum(f.change), unit) +
          (rel === null ? '' : ' (' + (rel >= 0 ? '+' : '') + (100 * rel).toFixed(1) + ' %)')}),
        el('td', {class: 'num', text: healthNum(f.z) === null ? '–' : healthNum(f.z).toFixed(1)}),
        el('td', {class: 'nowrap', text: f.since || ''}),
        el('td', {class: 'num', text: drift === null ? '–' : VBFormat.value(drift, unit)}),
        el('td', {class: 'long', text: f.meaning || ''}));
    })));
  } else {
    sec.append(el('p', {class: 'health-clean', text: 'No parameter flagged over ' + nights.length + ' nights.'}));
  }
  const grid = el('div', {class: 'chart-grid2'});
  sec.append(grid);
  const x0 = nights.length ? ' (1 = ' + nights[0] + ')' : '';
  for (const p of b.parameters || []) parameterChart(grid, p, nights, x0);
  // Each night's fit against its noise floor: a night the identification could not fit shows here first.
  const fits = nights.map((n, k) => [k + 1, healthNum((b.fit_rmse_A || [])[k]), healthNum((b.noise_floor_A || [])[k])]);
  if (fits.length) {
    VBCharts.plot(grid, {title: 'Fit of each night (RMS) and its noise floor', class: 'health-fit', x: {label: 'night' + x0, unit: ''},
      y: {label: 'RMS', unit: 'A'}, series: [{name: 'fit RMS', color: VBCharts.PALETTE[0], points: true},
        {name: 'noise floor', color: VBCharts.PALETTE[8], dash: [4, 3]}], rows: fits, height: 200, pad: 0.05}, cleanups);
  }
  if ((b.notes || []).length) sec.append(el('ul', {class: 'muted health-notes'}, b.notes.map((n) => el('li', {text: n}))));
  if (b.report) sec.append(el('details', {}, el('summary', {text: 'the tracking as benchctl health prints it'}), el('pre', {class: 'report', text: b.report})));
}

// One parameter's trend: the value each night (points; the identification's 1-sigma in the hover), the
// reference's mean and limits (dashed), the nights since the change started shaded when it was flagged.
function parameterChart(grid, p, nights, x0) {
  const v = p.value || [], s = p.sigma || [];
  const center = healthNum(p.center), lo = healthNum(p.lower_limit), hi = healthNum(p.upper_limit);
  const rows = nights.map((n, k) => [k + 1, healthNum(v[k]), center, lo, hi]);
  const flagged = p.flagged_night ? nights.indexOf(p.flagged_night) : -1;
  const since = p.change_since && flagged >= 0 ? nights.indexOf(p.change_since) : -1;
  const title = p.name + (p.meaning ? ' — ' + p.meaning : '');
  const c = VBCharts.plot(grid, {title, class: 'health-parameter' + (flagged >= 0 ? ' flagged' : ''), x: {label: 'night' + x0, unit: ''},
    y: {label: p.name, unit: p.unit || ''}, rows, height: 220, pad: 0.05,
    series: [{name: p.name, color: flagged >= 0 ? VBCharts.PALETTE[1] : VBCharts.PALETTE[0], points: true, connect: true},
      {name: 'reference mean', color: VBCharts.PALETTE[8], dash: [6, 3]},
      {name: 'lower limit (-3 sigma)', color: VBCharts.PALETTE[3], dash: [2, 2]},
      {name: 'upper limit (+3 sigma)', color: VBCharts.PALETTE[3], dash: [2, 2]}],
    band: since >= 0 ? [since + 0.5, nights.length + 0.5] : null,
    labels: flagged >= 0 && healthNum(v[flagged]) !== null ? [{x: flagged + 1, y: healthNum(v[flagged]), text: 'flagged ' + p.flagged_night,
      color: VBCharts.PALETTE[1]}] : []}, cleanups);
  c.box.dataset.parameter = p.name;
  const step = healthNum(p.smallest_detectable_step), drift = healthNum(p.drift_per_night), last = healthNum(v[v.length - 1]);
  const sig = s.length ? healthNum(s[s.length - 1]) : null;
  c.box.append(el('div', {class: 'muted health-caption', text: flagged >= 0
    ? 'flagged ' + p.flagged_night + ', changed since ' + (p.change_since || '?') + (drift === null ? '' : '; drifting ' + VBFormat.value(drift, p.unit || '') + ' per night since')
    : 'no change seen' + (step === null ? '' : '; the smallest step flagged within 5 nights on average: ' + VBFormat.value(step, p.unit || '') +
      (center ? ' (' + (100 * step / Math.abs(center)).toPrecision(2) + ' %)' : ''))
      + (sig === null || last === null ? '' : '; last night ' + VBFormat.value(last, p.unit || '') + ' ± ' + VBFormat.value(sig, p.unit || ''))}));
}
