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

  // The unit's first factor, its power and the rest ("m^2/m" -> m, 2, "^2/m"): common/units.cc's Split.
  function split(unit) {
    let end = unit.search(/[ /*]/);
    if (end < 0) end = unit.length;
    let head = unit.slice(0, end), rest = unit.slice(end), power = 1;
    const caret = head.indexOf('^');
    if (caret >= 0) { power = parseFloat(head.slice(caret + 1)); rest = head.slice(caret) + rest; head = head.slice(0, caret); }
    return {base: head, power, rest};
  }
  function unprefixed(unit) {
    return !unit || unit === '1' || unit === '%' || unit === 'turns' || unit === 'count' || unit === 'K' || /^[0-9.]/.test(unit);
  }

  // {symbol, scale, unit} for values of largest magnitude `maxAbs` in SI `unit`: the rule of common/units.h.
  // Compound units take the prefix on their first factor raised to its power (m^2 -> mm^2 is 1e6), the
  // kilogram is a prefixed gram (kg -> g, mg; kg/s -> mg/s). `unit` is the prefixed unit to print.
  function prefixFor(maxAbs, unit) {
    if (!prefixes || unprefixed(unit)) return {symbol: '', scale: 1, unit: unit || ''};
    const f = split(unit);
    let toBase = 1;
    if (f.base === 'kg') { f.base = 'g'; toBase = Math.pow(1e3, f.power); }
    let p = null;
    if (maxAbs > 0 && isFinite(maxAbs)) {
      p = prefixes[prefixes.length - 1];
      for (const q of prefixes) if (maxAbs * toBase * Math.pow(q.scale, f.power) >= 1 - 1e-12) { p = q; break; }
    } else {
      p = prefixes.find((q) => q.symbol === (toBase !== 1 ? 'k' : '')) || {symbol: '', scale: 1};
    }
    return {symbol: p.symbol, scale: toBase * Math.pow(p.scale, f.power), unit: p.symbol + f.base + f.rest};
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
    const p = prefixFor(Math.abs(x), unit);
    const suffix = p.unit && p.unit !== '1' ? ' ' + p.unit : '';
    if (x === 0) return '0' + suffix;
    const y = x * p.scale;
    const digits = Number.isInteger(y) && Math.abs(y) < 1e9 ? String(y) : String(parseFloat(y.toPrecision(4)));
    return digits + suffix;
  }

  // Axis ticks between lo and hi (about `n`): nice steps 1, 2, 5 × 10^k, labelled in the prefixed unit with as
  // many decimals as the step needs (never "0.0003" five times).
  function ticks(lo, hi, n, unit) {
    if (!(hi > lo) || !isFinite(lo) || !isFinite(hi)) return {ticks: [], symbol: '', scale: 1, unit: unit || ''};
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
    return {ticks: out, symbol: p.symbol, scale: p.scale, unit: p.unit};
  }

  return {load, use, prefixFor, cell, value, ticks};
})();
