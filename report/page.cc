// The HTML page of a report: CSS, the data as JSON, Debian's dygraphs and the web dashboard's chart code
// (web/static/format.js, charts.js, charts.css) inlined, and the renderer that hands each section to that code
// (the regression's bars excepted: inline SVG). No network.
#include <ctime>
#include <string>

#include "report/dygraphs.h"
#include "report/report.h"

#include "experiment/compare.h"

namespace vb::report {
namespace {

constexpr const char* kCss = R"css(
body { font: 14px/1.4 system-ui, sans-serif; margin: 20px 28px; color: #222; background: #fff; max-width: 1320px; }
section { max-width: 100%; }
h1 { font-size: 20px; margin: 0 0 4px; } p.made { font-size: 12px; color: #666; margin: 0 0 6px; } h2 { font-size: 16px; margin: 26px 0 8px; } h3 { font-size: 14px; margin: 14px 0 4px; }
#vb-status { display: none; } #vb-status.bad { display: block; color: #c00; font-weight: bold; font-size: 14px; }
.scroll { overflow-x: auto; max-width: 100%; }
table { border-collapse: collapse; font-size: 12px; margin: 4px 0 10px; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
table.meta td:first-child { font-weight: 600; background: #fafafa; }
table.meta td { white-space: normal; max-width: 1100px; }
details { margin: 6px 0; } summary { cursor: pointer; font-weight: 600; }
pre.spec { font-size: 11px; background: #f8f8f8; padding: 6px 8px; overflow-x: auto; max-height: 320px; }
th, td { border: 1px solid #ddd; padding: 3px 7px; text-align: left; white-space: nowrap; }
th { background: #f3f3f3; }
tr.regressed td { background: #fde2e2; } tr.improved td { background: #e3f6e3; } tr.new td { background: #e6eefc; }
p.note { padding: 6px 10px; background: #f6f6f6; border-left: 4px solid #999; }
p.note.good { border-color: #2a2; background: #eef9ee; } p.note.bad { border-color: #c22; background: #fcecec; }
svg.plot { display: block; background: #fff; user-select: none; width: 100%; max-width: 1200px; height: auto; }
svg.plot .band { fill: rgba(255, 200, 0, 0.16); }
svg.plot text { font: 11px system-ui, sans-serif; fill: #333; }
svg.plot .grid { stroke: #eee; } svg.plot .axis { stroke: #999; fill: none; }
p.band { font-size: 11px; color: #666; margin: 0 0 8px; }
)css";

constexpr const char* kJs = R"js(
(function () {
  'use strict';
  var status = document.getElementById('vb-status');
  var failed = false;
  window.onerror = function (msg, src, line) {
    failed = true;
    status.textContent = 'render-error: ' + msg + ' (line ' + line + ')';
    status.className = 'bad';
  };
  var NS = 'http://www.w3.org/2000/svg';
  var COLORS = VBCharts.PALETTE;  // the dashboard's palette
  var VERDICT_COLORS = {regressed: '#d62728', improved: '#2ca02c', unchanged: '#999999', 'new': '#1f77b4'};
  var plots = 0;

  function svgEl(tag, attrs, parent) {
    var e = document.createElementNS(NS, tag);
    for (var k in attrs) e.setAttribute(k, attrs[k]);
    if (parent) parent.appendChild(e);
    return e;
  }
  function html(tag, text, parent, cls) {
    var e = document.createElement(tag);
    if (text !== null && text !== undefined) e.textContent = text;
    if (cls) e.className = cls;
    if (parent) parent.appendChild(e);
    return e;
  }
  function finite(v) { return typeof v === 'number' && isFinite(v); }
  function fmt(v) {
    if (!finite(v)) return 'n/a';
    var a = Math.abs(v);
    if (a !== 0 && (a < 1e-3 || a >= 1e5)) return v.toExponential(2);
    return String(+v.toPrecision(4));
  }
  function ticks(lo, hi, n) {
    var span = hi - lo;
    if (!(span > 0)) return [lo];
    var step = Math.pow(10, Math.floor(Math.log10(span / n)));
    var err = span / n / step;
    if (err >= 7.5) step *= 10; else if (err >= 3.5) step *= 5; else if (err >= 1.5) step *= 2;
    var out = [];
    for (var v = Math.ceil(lo / step) * step; v <= hi + step * 1e-9; v += step) out.push(Math.abs(v) < step * 1e-9 ? 0 : v);
    return out;
  }
  function extent(arrays, lo0, hi0) {
    var lo = Infinity, hi = -Infinity;
    arrays.forEach(function (a) {
      for (var k = 0; k < a.length; k++) {
        var v = a[k];
        if (finite(v)) { if (v < lo) lo = v; if (v > hi) hi = v; }
      }
    });
    if (lo === Infinity) { lo = lo0 !== undefined ? lo0 : 0; hi = hi0 !== undefined ? hi0 : 1; }
    if (lo === hi) { var d = Math.abs(lo) * 0.05 + 1e-12; lo -= d; hi += d; }
    return [lo, hi];
  }

  // Every chart is drawn by the web dashboard's own code, inlined above (web/static/charts.js over Debian's
  // dygraphs; format.js for the numbers): the same axes with SI-prefixed units from the CLI's prefix table (carried
  // in the page's data), legends below the charts, one colour per law on every chart, SVG and PNG per chart. The
  // regression's bars alone are this page's SVG. With '#svg' in the address (`benchctl report --svg/--png`) each
  // chart's SVG form (VBCharts.toSvg) is also put in the page as an <svg class="plot"> for report/export.cc.
  var SVG_MODE = /svg/.test(location.hash);
  var ALL_RUNS = /all/.test(location.hash);
  var data = JSON.parse(document.getElementById('vb-data').textContent);
  VBFormat.use(data.units);
  var palette = new VBCharts.Palette();
  var BASE_UNITS = ['A', 'V', 'W', 's', 'Hz', 'J', 'm', 'Pa', 'N', 'H', 'Ohm'];

  // "current [mA]" -> {label: 'current', unit: 'A', factor: 1e-3}: values times factor are SI, and the shared
  // formatter prefixes the axis for the range shown. A unit that is no SI unit with a prefix ("%", "bar") stays
  // in the label, unprefixed.
  function axis(text) {
    var m = /^(.*?)\s*\[([^\]]+)\]\s*$/.exec(text || '');
    if (!m) return {label: text || '', unit: '', factor: 1};
    var u = m[2];
    if (BASE_UNITS.indexOf(u) >= 0) return {label: m[1], unit: u, factor: 1};
    var hit = data.units.prefixes.filter(function (p) {
      return p.symbol && u.indexOf(p.symbol) === 0 && BASE_UNITS.indexOf(u.slice(p.symbol.length)) >= 0;
    })[0];
    if (hit) return {label: m[1], unit: u.slice(hit.symbol.length), factor: 1 / hit.scale};
    return {label: text, unit: '', factor: 1};
  }
  // Series with their own x merged into dygraphs rows on one x axis (gaps bridged by the series' `connect`).
  function mergeRows(list, xf, yf) {
    var rows = new Map(), n = list.length;
    list.forEach(function (s, i) {
      for (var k = 0; k < s.x.length; k++) {
        var x = s.x[k];
        if (!finite(x)) continue;
        x *= xf;
        var row = rows.get(x);
        if (!row) { row = [x]; for (var j = 0; j < n; j++) row.push(null); rows.set(x, row); }
        row[i + 1] = finite(s.y[k]) ? s.y[k] * yf : null;
      }
    });
    return Array.from(rows.values()).sort(function (p, q) { return p[0] - q[0]; });
  }
  var made = [];  // every drawn chart: {c} (dygraphs) or {box} (SVG), for the '#svg' export
  function chart(parent, opts) {
    plots++;
    var c = VBCharts.plot(parent, opts);
    made.push({c: c});
    return c;
  }
  // A line chart of series {name, x, y, color, dash, width, step, points} with x/y labels "name [unit]".
  function lineChart(parent, title, xText, yText, list, more) {
    var xa = axis(xText), ya = axis(yText);
    var opts = {title: title, x: {label: xa.label, unit: xa.unit}, y: {label: ya.label, unit: ya.unit},
                rows: mergeRows(list, xa.factor, ya.factor), height: 260,
                series: list.map(function (s) {
                  return {name: s.name, color: s.color, dash: dashOf(s.dash), width: s.width, step: !!s.step,
                          points: !!s.points, connect: true};
                })};
    for (var k in more || {}) opts[k] = more[k];
    if (opts.band) opts.band = [opts.band[0] * xa.factor, opts.band[1] * xa.factor];
    return chart(parent, opts);
  }
  // Law colours when each law is one case (as the Compare page: PI green everywhere); when a law has several
  // cases (variants of a plant), each case its own colour, or they could not be told apart.
  function fixLaws(items, nameOf) {
    var seen = {}, once = true;
    items.forEach(function (it) { if (it.controller) { once = once && !seen[it.controller]; seen[it.controller] = true; } });
    if (once) items.forEach(function (it) { palette.fixLaw(nameOf(it), it.controller); });
  }
  function dashOf(text) { return text ? String(text).split(',').map(Number) : null; }

  function drawRun(run, box) {
    var charts = [];
    if (run.gate)
      charts.push(lineChart(box, 'gate', 't [s]', 'gate', [{name: 'gate', x: run.t, y: run.gate, step: true, color: '#555'}],
                            {height: 110, y: {label: 'gate', logic: true}}));
    if (run.i_A) {
      var s = [{name: 'i', x: run.t, y: run.i_A, color: VBCharts.PALETTE[0]}];
      if (run.ref && run.controlled === 'current') s.push({name: 'reference', x: run.t, y: run.ref, color: '#000', dash: '5,3', width: 1});
      charts.push(lineChart(box, 'current', 't [s]', 'current [A]', s));
    }
    if (run.x_m) {
      var p = [{name: 'x', x: run.t, y: run.x_m, color: VBCharts.PALETTE[2]}];
      if (run.ref && run.controlled === 'position') p.push({name: 'reference', x: run.t, y: run.ref, color: '#000', dash: '5,3', width: 1});
      charts.push(lineChart(box, 'position', 't [s]', 'position [m]', p));
    }
    VBCharts.linkTime(charts);
  }

  // Every run is reachable: one collapsible block per run, the first `open` drawn at once, the rest when opened.
  function renderTraces(sec, box) {
    if (!sec.runs || sec.runs.length === 0) { html('p', 'No traces stored for these runs.', box, 'note'); return; }
    var open = sec.open === undefined || ALL_RUNS ? sec.runs.length : sec.open;
    sec.runs.forEach(function (run, i) {
      var d = html('details', null, box);
      html('summary', run.label + ' (' + run.samples + ' samples)', d);
      var drawn = false;
      function draw() { if (!drawn) { drawn = true; drawRun(run, d); } }
      if (i < open) { d.open = true; draw(); }
      d.addEventListener('toggle', function () { if (d.open) draw(); });
    });
  }

  function renderMeta(sec, box) {
    var wrap = html('div', null, box, 'scroll');
    var t = html('table', null, wrap, 'meta');
    (sec.rows || []).forEach(function (row) {
      var r = html('tr', null, t);
      html('td', row[0], r);
      html('td', row[1], r);
    });
    if (sec.specs && sec.specs.length > 0) {
      var d = html('details', null, box);
      html('summary', 'Specs (' + sec.specs.length + ')', d);
      sec.specs.forEach(function (s) {
        html('div', s.label, d);
        html('pre', s.text, d, 'spec');
      });
    }
  }

  // The compared runs on shared axes: controlled variable and reference over the run (metric window shaded),
  // tracking error over the metric window; each law in its colour of every page.
  function renderOverlay(sec, box) {
    var ys = [], es = [];
    fixLaws(sec.series, function (s) { return s.name; });
    sec.series.forEach(function (s) {
      var e = palette.entry(s.name);
      ys.push({name: s.name, x: s.t, y: s.y, color: e.color, dash: e.dash ? e.dash.join(',') : null});
      es.push({name: s.name, x: s.et, y: s.e, color: e.color, dash: e.dash ? e.dash.join(',') : null});
    });
    if (sec.series.length > 0) {
      var r = sec.series[0];
      ys.push({name: 'reference', x: r.t, y: r.ref, color: '#000', dash: '5,3', width: 1});
    }
    var w = sec.window;
    var a = lineChart(box, sec.y_label.replace(/ \[.*$/, '') + ' and reference', 't [s]', sec.y_label, ys, {height: 300, band: w});
    html('p', 'metric window ' + VBFormat.value(w[0], 's') + ' to ' + VBFormat.value(w[1], 's') + ' shaded', box, 'band');
    html('h3', 'Tracking error over the metric window ' + VBFormat.value(w[0], 's') + ' to ' + VBFormat.value(w[1], 's'), box);
    var b = lineChart(box, 'tracking error', 't [s]', sec.e_label, es, {height: 260, band: w});
    VBCharts.linkTime([a, b]);
  }

  function renderTable(sec, box) {
    if (sec.collapsed) {
      box = html('details', null, box);
      html('summary', (sec.rows || []).length + ' rows', box);
    }
    var t = html('table', null, html('div', null, box, 'scroll'));
    var tr = html('tr', null, t);
    (sec.columns || []).forEach(function (c) { html('th', c, tr); });
    var caseCol = (sec.columns || []).indexOf('case');
    (sec.rows || []).forEach(function (row, i) {
      var r = html('tr', null, t, sec.row_classes ? sec.row_classes[i] : '');
      row.forEach(function (c, j) {
        var right = sec.left ? !sec.left[j] : typeof c === 'number';
        var td = html('td', c === null ? '' : (typeof c === 'number' ? fmt(c) : String(c)), r, right ? 'num' : '');
        // A case's swatch: its colour in the charts below (as the Compare page's table).
        if (j === caseCol && palette.map.has(String(c))) {
          var sw = document.createElement('i');
          sw.className = 'swatch';
          sw.style.background = palette.colorOf(String(c));
          td.insertBefore(sw, td.firstChild);
        }
      });
    });
  }

  // The Pareto scatter as the Compare page draws it (web/static/compare.js scatterChart): a point per case in its
  // law's colour, labelled beside it, the front joined by a dashed line, axes in the table's columns' units.
  function renderScatter(sec, box) {
    var pts = sec.points;
    fixLaws(pts, function (p) { return p.label; });
    var series = pts.map(function (p) { return {name: p.label, color: palette.colorOf(p.label), points: true, width: 0}; });
    var front = pts.filter(function (p) { return p.front; }).sort(function (p, q) { return p.x - q.x; });
    series.push({name: 'Pareto front', color: '#555', width: 1.5, dash: [6, 3], connect: true});
    var rows = pts.map(function (p, k) { var r = new Array(pts.length + 2).fill(null); r[0] = p.x; r[k + 1] = p.y; return r; });
    front.forEach(function (p) { var r = new Array(pts.length + 2).fill(null); r[0] = p.x; r[pts.length + 1] = p.y; rows.push(r); });
    rows.sort(function (p, q) { return p[0] - q[0]; });
    chart(box, {title: sec.y_label + ' vs ' + sec.x_label, class: 'pareto', x: {label: sec.x_label, unit: ''},
                y: {label: sec.y_label, unit: ''}, series: series, rows: rows, pad: 0.12, height: 360,
                labels: pts.map(function (p) { return {x: p.x, y: p.y, text: p.label, color: palette.colorOf(p.label)}; })});
  }

  function renderBars(sec, box) {
    var n = sec.labels.length, rowH = 20, W = 1200;
    var longest = sec.labels.reduce(function (m, l) { return Math.max(m, String(l).length); }, 0);
    var M = {l: Math.min(560, 16 + 6.6 * longest), r: 70, t: 10, b: 30};
    var H = M.t + M.b + n * rowH;
    var svg = svgEl('svg', {viewBox: '0 0 ' + W + ' ' + H, 'class': 'plot'}, box);
    plots++;
    var lims = sec.limits || [];
    var xr = extent([sec.values.concat(lims).concat([0])]);
    var pad = (xr[1] - xr[0]) * 0.05;
    xr = [xr[0] - pad, xr[1] + pad];
    function px(x) { return M.l + (x - xr[0]) / (xr[1] - xr[0]) * (W - M.l - M.r); }
    ticks(xr[0], xr[1], 8).forEach(function (t) {
      svgEl('line', {x1: px(t), x2: px(t), y1: M.t, y2: H - M.b, 'class': 'grid'}, svg);
      svgEl('text', {x: px(t), y: H - M.b + 14, 'text-anchor': 'middle'}, svg).textContent = fmt(t);
    });
    sec.values.forEach(function (v, i) {
      var y = M.t + i * rowH;
      var color = sec.classes ? (VERDICT_COLORS[sec.classes[i]] || '#1f77b4') : COLORS[0];
      var a = px(Math.min(0, v)), b = px(Math.max(0, v));
      svgEl('rect', {x: a, y: y + 3, width: Math.max(1, b - a), height: rowH - 6, fill: color}, svg);
      svgEl('text', {x: M.l - 6, y: y + rowH / 2 + 4, 'text-anchor': 'end'}, svg).textContent = sec.labels[i];
      svgEl('text', {x: b + 4, y: y + rowH / 2 + 4}, svg).textContent = fmt(v);
    });
    svgEl('line', {x1: px(0), x2: px(0), y1: M.t, y2: H - M.b, stroke: '#333'}, svg);
    lims.forEach(function (l) {
      svgEl('line', {x1: px(l), x2: px(l), y1: M.t, y2: H - M.b, stroke: '#d62728', 'stroke-dasharray': '4,3'}, svg);
    });
  }

  // Curves (a static map's sweep, a diagnosis's measured and model currents). A sweep's curves (markers: one
  // per value of the other axis) are also shown as a heat map over both axes, as the Compare page shows a sweep.
  function renderLines(sec, box) {
    var list = (sec.series || []).map(function (s) {
      var e = palette.entry(s.name);
      return {name: s.name, x: s.x, y: s.y, color: e.color, dash: dashOf(s.dash) ? s.dash : (e.dash ? e.dash.join(',') : null),
              width: s.width, points: !!sec.markers};
    });
    list.forEach(function (s) { s.dash = dashOf(s.dash); });
    var xa = axis(sec.x_label), ya = axis(sec.y_label);
    var opts = {title: sec.y_label + ' against ' + sec.x_label, x: {label: xa.label, unit: xa.unit}, y: {label: ya.label, unit: ya.unit},
                rows: mergeRows(list, xa.factor, ya.factor), height: 340,
                series: list.map(function (s) {
                  return {name: s.name, color: s.color, dash: s.dash, width: s.width, points: s.points, connect: true};
                })};
    var main = chart(box, opts);
    // A diagnosis overlay: under it the residual, measured - model before (nominal) and after (fitted), on the
    // same time axis, as the dashboard's Diagnosis page shows it.
    var measured = list.filter(function (q) { return q.name === 'measured'; })[0];
    var models = list.filter(function (q) { return q.name === 'nominal' || q.name === 'fitted'; });
    if (measured && models.length) {
      var res = models.map(function (q) {
        return {name: 'measured − ' + q.name + (q.name === 'nominal' ? ' (before)' : ' (after)'), x: q.x,
                color: q.color, width: 1.3,
                y: q.y.map(function (v, k) { return finite(v) && finite(measured.y[k]) ? measured.y[k] - v : null; })};
      });
      var r = lineChart(box, 'residual: measured − model', sec.x_label, sec.y_label.replace(/^.*\[/, 'measured − model ['),
                        res, {height: 160});
      VBCharts.linkTime([main, r]);
    }
    if (sec.markers && list.length > 1) {
      var xs = [];
      list.forEach(function (s) { s.x.forEach(function (x) { if (xs.indexOf(x) < 0) xs.push(x); }); });
      xs.sort(function (p, q) { return p - q; });
      if (xs.length > 1) {
        plots++;
        var hm = VBCharts.heatmap(box, {
          title: sec.y_label + ' over ' + sec.x_label + ' and curve',
          x: {label: sec.x_label, values: xs, fmt: function (v) { return String(+v.toPrecision(4)); }},
          y: {label: 'curve', values: list.map(function (s) { return s.name; }), fmt: String},
          z: {label: sec.y_label.replace(/ \[.*$/, ''), fmt: function (v) { return String(+v.toPrecision(3)); },
              get: function (x, name) {
                var s = list.filter(function (q) { return q.name === name; })[0];
                var k = s ? s.x.indexOf(x) : -1;
                return k >= 0 && finite(s.y[k]) ? s.y[k] : null;
              }}});
        made.push({box: hm});
      }
    }
  }

  var root = document.getElementById('vb-report');
  var renderers = {traces: renderTraces, table: renderTable, scatter: renderScatter, bars: renderBars, lines: renderLines,
                   meta: renderMeta, overlay: renderOverlay,
                   note: function (sec, box) { html('p', sec.text, box, 'note ' + (sec['class'] || '')); }};
  var count = 0;
  // The cases' colours first (scatter, then overlays), so that the comparison table above them shows them too.
  data.sections.forEach(function (sec) {
    if (sec.kind === 'scatter') { fixLaws(sec.points, function (p) { return p.label; }); sec.points.forEach(function (p) { palette.entry(p.label); }); }
    if (sec.kind === 'overlay') { fixLaws(sec.series, function (x) { return x.name; }); sec.series.forEach(function (x) { palette.entry(x.name); }); }
  });
  data.sections.forEach(function (sec) {
    var box = html('section', null, root);
    if (sec.title && sec.kind !== 'table') html('h2', sec.title, box);
    if (sec.title && sec.kind === 'table') html('h2', sec.title, box);
    var r = renderers[sec.kind];
    if (!r) throw new Error('unknown section kind ' + sec.kind);
    r(sec, box);
    count++;
  });
  // '#svg': each chart's vector form after it, for report/export.cc (namespace and size are added there).
  if (SVG_MODE)
    made.forEach(function (m) {
      var svg = m.c ? (m.c.g ? VBCharts.toSvg(m.c) : null) : m.box.querySelector('svg').cloneNode(true);
      if (!svg) return;
      ['xmlns', 'width', 'height'].forEach(function (k) { svg.removeAttribute(k); });
      svg.setAttribute('class', 'plot');
      (m.c ? m.c.box : m.box).after(svg);
    });
  if (!failed) {
    status.textContent = 'rendered-ok: ' + count + ' sections, ' + plots + ' plots';
    document.body.setAttribute('data-vb-status', 'ok');
  }
  // For the layout test: the page must not scroll sideways (docs/report.md).
  document.body.setAttribute('data-vb-overflow-px',
                             String(Math.max(0, document.documentElement.scrollWidth - document.documentElement.clientWidth)));
})();
)js";

// Every page says when it was made (docs/report.md): UTC, to the second.
std::string MadeAt() {
  const std::time_t t = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%d %H:%M:%S UTC", &tm);
  return buf;
}

std::string EscapeHtml(const std::string& s) {
  std::string out;
  for (char c : s) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      default: out += c;
    }
  }
  return out;
}

// JSON inside <script>: "</" would end the element; "<\/" is the same JSON string.
std::string ScriptSafe(const std::string& json) {
  std::string out;
  out.reserve(json.size());
  for (std::size_t k = 0; k < json.size(); ++k) {
    if (json[k] == '<' && k + 1 < json.size() && (json[k + 1] == '/' || json[k + 1] == '!')) {
      out += "\\u003c";
      continue;
    }
    out += json[k];
  }
  return out;
}

}  // namespace

std::string RenderHtml(const std::string& title, const Json& sections) {
  // The SI prefix table the CLI chooses from (format.js's /api/units on the dashboard): the charts' axes use it.
  Json prefixes = Json::array();
  for (const auto& p : experiment::SiPrefixes()) prefixes.push_back({{"symbol", p.symbol}, {"scale", p.scale}});
  Json data = {{"title", title},
               {"units", {{"prefixes", prefixes}}},
               {"sections", sections.is_array() ? sections : Json::array()}};
  std::string out;
  out += "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>";
  out += EscapeHtml(title);
  out += "</title>\n<link rel=\"icon\" href=\"data:,\">\n<style>";
  out += kCss;
  out += "</style>\n";
  // dygraphs as Debian ships it (MIT licence comment kept), without its source-map line: nothing to fetch; then
  // the dashboard's format.js, charts.js and charts.css (report/CMakeLists.txt embeds them in that order).
  for (const Asset& a : Assets()) {
    std::string_view body = a.body();
    if (const size_t map = body.rfind("//# sourceMappingURL="); map != std::string_view::npos) body = body.substr(0, map);
    if (const size_t map = body.rfind("/*# sourceMappingURL="); map != std::string_view::npos) body = body.substr(0, map);
    const bool css = std::string_view(a.url_path).ends_with(".css");
    out += css ? "<style>" : "<script>";
    out += body;
    out += css ? "</style>\n" : "</script>\n";
  }
  out += "</head>\n<body>\n<h1>";
  out += EscapeHtml(title);
  out += "</h1>\n<p class=\"made\">page made " + MadeAt() + " by benchctl report</p>\n<div id=\"vb-status\">rendering... (needs JavaScript)</div>\n<div id=\"vb-report\"></div>\n";
  out += "<script type=\"application/json\" id=\"vb-data\">";
  out += ScriptSafe(data.dump(-1, ' ', false, Json::error_handler_t::replace));
  out += "</script>\n<script>";
  out += kJs;
  out += "</script>\n</body>\n</html>\n";
  return out;
}

}  // namespace vb::report
