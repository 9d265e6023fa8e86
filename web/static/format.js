// valvebench web dashboard (docs/web.md "Units"): numbers for people, formatted as the CLI's tables format them.
// The rule is the C++ one (experiment::MetricColumnDisplay): the gateway sends, with each comparison, every
// column's label, prefixed unit, scale and decimals; for chart axes and single values the page applies the SI
// prefix table the CLI chooses from (/api/units: experiment::SiPrefixes), largest prefix first, the first whose
// scale puts the largest magnitude at 1 or above. Nothing here decides a unit or a prefix list of its own.
'use strict';

const VBFormat = (() => {
  // Filled from /api/units at start; this copy only until then (the page's first chart waits for it anyway).
  let prefixes = null;

  async function load(fetchJson) {
    if (prefixes) return;
    const u = await fetchJson('/api/units');
    prefixes = u.prefixes;
  }

  // The same table handed over directly (the HTML report carries it in its data: no server to ask).
  function use(units) {
    if (!units || !Array.isArray(units.prefixes) || !units.prefixes.length) throw new Error('units: no SI prefix table');
    prefixes = units.prefixes;
  }

  // {symbol, scale} for a value range of the largest magnitude `maxAbs` (unit "" or "1": no prefix).
  function prefixFor(maxAbs, unit) {
    if (!prefixes || !unit || unit === '1' || unit === '%' || !(maxAbs > 0) || !isFinite(maxAbs)) return {symbol: '', scale: 1};
    for (const p of prefixes) if (maxAbs * p.scale >= 1 - 1e-12) return p;
    return prefixes[prefixes.length - 1];
  }

  // A stat {mean, spread, n} in a column shown as `d` (the gateway's display): "12.34", "12.34 ± 0.5", "0", "–".
  function cell(stat, d) {
    if (!stat || typeof stat.mean !== 'number' || !(stat.n > 0)) return '–';
    const x = stat.mean * d.scale;
    let s = stat.mean === 0 ? '0' : x.toFixed(d.decimals);
    if (stat.n > 1) s += ' ± ' + (stat.spread ? (stat.spread * d.scale).toFixed(d.spread_decimals) : '0');
    return s;
  }

  // One value with its unit and an SI prefix on its own magnitude, 4 significant digits: "537.5 µA", "0 A", "–".
  function value(v, unit) {
    if (v === null || v === undefined || v === '' || (typeof v === 'number' && !isFinite(v)) || isNaN(Number(v))) return '–';
    const x = Number(v);
    if (x === 0) return '0' + (unit && unit !== '1' ? ' ' + unit : '');
    const p = prefixFor(Math.abs(x), unit);
    const y = x * p.scale;
    const digits = Number.isInteger(y) && Math.abs(y) < 1e9 ? String(y) : String(parseFloat(y.toPrecision(4)));
    return digits + (unit && unit !== '1' ? ' ' + p.symbol + unit : '');
  }

  // Axis ticks between lo and hi (about `n`): nice steps 1, 2, 5 × 10^k, labelled in the prefixed unit with as
  // many decimals as the step needs (never "0.0003" five times).
  function ticks(lo, hi, n, unit) {
    if (!(hi > lo) || !isFinite(lo) || !isFinite(hi)) return {ticks: [], symbol: '', scale: 1};
    const p = prefixFor(Math.max(Math.abs(lo), Math.abs(hi)), unit);
    let step = Math.pow(10, Math.floor(Math.log10((hi - lo) / n)));
    const err = (hi - lo) / n / step;
    if (err >= 7.5) step *= 10; else if (err >= 3.5) step *= 5; else if (err >= 1.5) step *= 2;
    const decimals = Math.max(0, -Math.floor(Math.log10(step * p.scale) + 1e-9));
    const out = [];
    for (let k = Math.ceil(lo / step - 1e-9); k * step <= hi + step * 1e-9; k++) {
      const v = k * step;
      out.push({v, label: (Math.abs(v) < step * 1e-9 ? 0 : v * p.scale).toFixed(Math.min(decimals, 9))});
    }
    return {ticks: out, symbol: p.symbol, scale: p.scale};
  }

  return {load, use, prefixFor, cell, value, ticks};
})();
