// valvebench web dashboard: the Diagnosis page (docs/web.md "Diagnosis"). The imported measured runs by dataset;
// "diagnose" runs the sim-to-real gap diagnosis on the server (DiagnoseRuns, as `benchctl diagnose --runs`) and
// shows it as pictures: the verdict with its size, measured against the nominal and the improved model per
// run, the residual by phase before and after the effect, the detection limits, the report and the improved
// model to download.
'use strict';

let diagnosisBusy = false;

async function runDiagnosis(ids, out) {
  if (diagnosisBusy) return;
  diagnosisBusy = true;
  const buttons = Array.from(document.querySelectorAll('button.diagnose'));
  for (const b of buttons) { b.disabled = true; b.title = 'a diagnosis is running'; }
  const t0 = Date.now();
  const elapsed = el('span', {class: 'elapsed', text: '0 s'});
  out.replaceChildren(el('div', {class: 'diagnosis-progress'},
    el('p', {}, 'Diagnosing ' + ids.length + ' runs on the server (fits every candidate effect; typically 10 s to a minute): ', elapsed),
    el('div', {class: 'progress-bar'}, el('div'))));
  const timer = setInterval(() => { elapsed.textContent = Math.round((Date.now() - t0) / 1000) + ' s'; }, 500);
  cleanups.push(() => clearInterval(timer));
  try {
    await VBFormat.load((p) => api('GET', p));
    const d = await api('GET', '/api/diagnose?runs=' + ids.join(','));
    if (out.isConnected) showDiagnosis(d, out, (Date.now() - t0) / 1000);
  } catch (e) { showError(e, out); } finally {
    clearInterval(timer);
    diagnosisBusy = false;
    for (const b of buttons) { b.disabled = false; b.title = ''; }
  }
}

function showDiagnosis(d, out, took_s) {
  const v = d.diagnosis || {};
  paramUnits = d.param_units || {};
  const A = (x) => VBFormat.value(x, 'A');
  const best = (v.ranking || [])[0] || null;
  const how = v.how_far || null;
  const palette = new VBCharts.Palette();
  // The verdict and its size: the effect, its fitted parameters, the hold-out gap before and after it.
  const verdict = el('div', {class: 'verdict-box'}, el('strong', {text: 'Verdict: '}),
    el('span', {class: 'verdict', text: String(v.verdict || '–')}),
    how ? el('span', {class: 'verdict-size'}, ' — closes ' + Math.round(100 * (how.closed || 0)) + ' % of the hold-out gap: RMSE ' +
      A(how.holdout_rmse_before_A) + ' → ' + A(how.holdout_rmse_after_A)) : null,
    best && best.effect === v.verdict && Object.keys(best.params || {}).length ?
      el('div', {class: 'verdict-params'}, Object.entries(best.params).map(([k, x], i) => [i ? '; ' : '', el('code', {text: k}), ' = ' +
        fmtParam(x, k) + (best.uncertainty && best.uncertainty[k] ? ' ± ' + fmtParam(best.uncertainty[k], k) : '')])) : null,
    el('div', {class: 'muted'}, v.verdict_reason || ''),
    el('div', {class: 'muted'}, 'gap: fit RMSE ' + A((v.gap || {}).fit_rmse_A) + ', hold-out RMSE ' + A((v.gap || {}).holdout_rmse_A) +
      ((v.gap || {}).significant ? ' (significant)' : ' (not significant)') + '; noise floor ' + A(v.noise_floor_A) +
      '; diagnosed in ' + took_s.toFixed(1) + ' s'));
  const model = d.improved_model_json || '';
  const actions = el('div', {class: 'actions'},
    model ? el('a', {id: 'improved-model', download: 'improved-model.json', class: 'button',
      href: URL.createObjectURL(new Blob([model], {type: 'application/json'})), text: 'download the improved model (JSON)'})
      : el('span', {class: 'muted', id: 'improved-model-none', text: v.verdict && v.verdict !== 'unknown' && v.verdict !== 'none' && v.verdict !== 'undetermined'
        ? 'the server sent no improved model (DiagnoseRunsResponse.improved_model_json is empty)' : 'no improved model (no effect attributed)'}),
    el('a', {download: 'diagnosis.json', href: URL.createObjectURL(new Blob([JSON.stringify(v, null, 2)], {type: 'application/json'})),
      text: 'diagnosis JSON'}),
    el('a', {download: 'diagnosis.txt', href: URL.createObjectURL(new Blob([d.report || ''], {type: 'text/plain'})), text: 'report (text)'}));
  out.replaceChildren(verdict, actions);
  // Measured against the nominal model (before) and the model with the effect (after), per run.
  const ovs = v.overlays || [];
  if (ovs.length) {
    const sec = el('section', {id: 'diagnosis-overlays'}, el('h2', {text: 'Measured and model, per run (before and after the effect)'}));
    const grid = el('div', {class: 'chart-grid2'});
    sec.append(grid);
    out.append(sec);
    const shown = ovs.slice(0, 8);
    if (ovs.length > shown.length) sec.insertBefore(el('p', {class: 'muted', text: 'the first ' + shown.length + ' of ' + ovs.length + ' runs'}), grid);
    for (const o of shown) {
      // The measurement wide and light underneath, the models thin over it: where they leave it shows.
      const series = [{name: 'measured', color: '#9aa0a6', width: 3.2}, {name: 'nominal model (before)', color: VBCharts.PALETTE[3], dash: [5, 3], width: 1.3}];
      const hasFit = (o.fitted_A || []).some((x) => typeof x === 'number');
      if (hasFit) series.push({name: 'with ' + (how ? how.candidate : 'the effect') + ' (after)', color: VBCharts.PALETTE[0], width: 1.1});
      const rows = (o.t_s || []).map((t, k) => [t, num(o.measured_A[k]), num(o.nominal_A[k])].concat(hasFit ? [num(o.fitted_A[k])] : []));
      const cell = el('div');
      grid.append(cell);
      const overlay = VBCharts.plot(cell, {title: 'run ' + o.run + ' (' + (o.split || 'fit') + ')', class: 'diagnosis-overlay',
        x: {label: 't', unit: 's'}, y: {label: 'i', unit: 'A'}, series, rows, height: 200}, cleanups);
      // Under it, the residual (measured - model) before and after the effect, on the same time axis (zoomed
      // together): what the effect removes, and what is left.
      const diff = (a, b) => (a === null || b === null ? null : a - b);
      const rseries = [{name: 'measured − nominal (before)', color: VBCharts.PALETTE[3], width: 1.3}];
      if (hasFit) rseries.push({name: 'measured − with ' + (how ? how.candidate : 'the effect') + ' (after)', color: VBCharts.PALETTE[0], width: 1.3});
      const rrows = rows.map((r) => [r[0], diff(r[1], r[2])].concat(hasFit ? [diff(r[1], r[3])] : []));
      const residual = VBCharts.plot(cell, {title: 'run ' + o.run + ': residual', class: 'diagnosis-residual',
        x: {label: 't', unit: 's'}, y: {label: 'measured − model', unit: 'A'}, series: rseries, rows: rrows, height: 140}, cleanups);
      VBCharts.linkTime([overlay, residual]);
    }
  }
  // The residual by phase: where the gap is, and how much of it the effect removes.
  const phases = (how && how.phases) || [];
  const where = v.where || [];
  if (phases.length || where.length) {
    const sec = el('section', {id: 'diagnosis-phases'}, el('h2', {text: 'Residual by phase'}));
    out.append(sec);
    if (phases.length)
      VBCharts.bars(sec, {title: 'Hold-out RMSE by phase, before and after ' + how.candidate, unit: 'A', label: 'RMSE',
        categories: phases.map((p) => p.phase), series: [
          {name: 'nominal model', color: VBCharts.PALETTE[3], values: phases.map((p) => p.holdout_rmse_before_A)},
          {name: 'with ' + how.candidate, color: VBCharts.PALETTE[0], values: phases.map((p) => p.holdout_rmse_after_A)}]});
    if (where.length)
      VBCharts.bars(sec, {title: 'Share of the residual energy by phase (nominal model)', unit: '%', label: 'share',
        categories: where.map((w) => w.phase), series: [{name: 'share of the residual energy', color: VBCharts.PALETTE[4],
          values: where.map((w) => 100 * w.share)}]});
  }
  // The candidates and the detection limits.
  const ranking = v.ranking || [];
  if (ranking.length)
    out.append(el('section', {}, el('h2', {text: 'Candidate effects'}), el('div', {class: 'scroll'}, el('table', {id: 'diagnosis-ranking'},
      el('tr', {}, ['effect', 'hold-out RMSE before', 'after', 'closed', 'signature', 'parameters'].map((t) => el('th', {text: t}))),
      ranking.slice(0, 12).map((r) => el('tr', {}, el('td', {text: r.effect}), el('td', {class: 'num', text: A(r.holdout_rmse_before_A)}),
        el('td', {class: 'num', text: A(r.holdout_rmse_after_A)}), el('td', {class: 'num', text: typeof r.closed === 'number' ? Math.round(100 * r.closed) + ' %' : '–'}),
        el('td', {class: 'num', text: typeof r.signature_match === 'number' ? r.signature_match.toFixed(2) : '–'}),
        el('td', {class: 'wrap', text: Object.entries(r.params || {}).map(([k, x]) => k + ' = ' + fmtParam(x, k)).join(', ')})))))));
  const limits = v.detection_limits || [];
  out.append(el('section', {id: 'detection-limits'}, el('h2', {text: 'Detection limits'}), limits.length === 0 ?
    el('p', {class: 'muted', text: 'No detection limits computed for this diagnosis.'}) :
    el('div', {class: 'scroll'}, el('table', {}, el('tr', {}, ['effect', 'detectable', 'smallest detectable', 'residual at the limit'].map((t) => el('th', {text: t}))),
      // Worded as benchctl diagnose words them (gap/diagnosis_report.cc): a limit at the searched range's end is
      // not the smallest change that shows, only a bound on it.
      limits.map((l) => el('tr', {}, el('td', {text: l.effect}), el('td', {text: !l.detectable ? 'no' : 'yes'}),
        el('td', {class: 'wrap', text: (Object.entries(l.params || {}).map(([k, x]) => k + ' = ' + fmtParam(x, k)).join(', ') || '–') +
          (!l.detectable ? ' (not detectable even there: the range\'s end)' : l.below_range ? ' (shown even there: the range\'s weakest)' : '')}),
        el('td', {class: 'num', text: A(l.residual_at_limit_A)})))))));
  out.append(el('section', {}, el('h2', {text: 'Report (as benchctl diagnose prints it)'}), el('pre', {class: 'report', text: d.report || ''})));
}

// A fitted parameter with its unit from the model's tables (the gateway's param_units), SI-prefixed.
let paramUnits = {};
function fmtParam(x, name) {
  if (typeof x !== 'number') return String(x);
  const u = paramUnits[name];
  return u ? VBFormat.value(x, u) : String(parseFloat(x.toPrecision(4)));
}

async function pageDiagnosis(main) {
  const box = el('div', {class: 'scroll'});
  const out = el('div', {id: 'diagnosis-report'});
  main.replaceChildren(el('h1', {text: 'Diagnosis'}), el('section', {},
    el('p', {}, 'The sim-to-real gap diagnosis of stored measured runs: where they depart from the model, which ' +
      'unmodelled effect explains it and how far it closes the gap on held-out runs (docs/gap.md). It runs on the ' +
      'server, as ', el('code', {text: 'benchctl diagnose --runs ID,ID,…'}), ' does.'), box), out);
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
            el('td', {}, el('button', {type: 'button', class: 'diagnose primary', 'data-batch': String(b), disabled: diagnosisBusy,
              onclick: () => runDiagnosis(runs.map((r) => r.id), out), text: 'diagnose'})),
            el('td', {}, el('a', {class: 'overlay', href: '#/compare?runs=' + runs.slice(0, 12).map((r) => r.id).join(','), text: 'overlay'})));
        })));
  } catch (e) { showError(e, box); }
}
