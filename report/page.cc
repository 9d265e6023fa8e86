// The HTML page of a report: CSS, the data as JSON, Debian's dygraphs inlined for the time series, and the
// renderer (vanilla JS; inline SVG for the scatter, the bars and the --svg/--png files; no network).
#include <ctime>
#include <string>

#include "report/dygraphs.h"
#include "report/report.h"

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
svg.plot .sel { fill: rgba(80, 120, 220, 0.15); stroke: #57c; }
.legend span { display: inline-block; margin-right: 14px; font-size: 12px; }
.dyplot { width: 100%; max-width: 1200px; padding: 0; margin: 0 0 4px; }
p.band { font-size: 11px; color: #666; margin: 0 0 8px; }
.legend i { display: inline-block; width: 14px; height: 3px; margin-right: 4px; vertical-align: middle; }
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
  var COLORS = ['#1f77b4', '#d62728', '#2ca02c', '#ff7f0e', '#9467bd', '#8c564b', '#e377c2', '#17becf', '#7f7f7f'];
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
  function tickLabel(v, ticksArr) {
    var step = ticksArr.length > 1 ? Math.abs(ticksArr[1] - ticksArr[0]) : Math.abs(v);
    if (!finite(v)) return 'n/a';
    if (v === 0) return '0';
    var decimals = Math.max(0, -Math.floor(Math.log10(step) + 1e-9));
    if (decimals <= 6 && Math.abs(v) < 1e6) return v.toFixed(decimals);
    return v.toExponential(Math.max(0, Math.floor(Math.log10(Math.abs(v))) - Math.floor(Math.log10(step))));
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

  // Time series are drawn by Debian's dygraphs, inlined in the page (the library the web dashboard serves,
  // docs/report.md "Chart library"). The SVG drawing below is for '#svg' pages only: `benchctl report --svg/--png`
  // loads the page so and writes each plot as a vector file, which a canvas cannot give.
  var SVG_MODE = /svg/.test(location.hash);
  var ALL_RUNS = /all/.test(location.hash);

  // A dygraphs plot of series that each have their own x: rows merged on one x axis, gaps bridged.
  function DyPlot(parent, opt) {
    var self = this;
    plots++;
    var div = html('div', null, parent, 'dyplot');
    div.style.height = (opt.height || 240) + 'px';
    var n = opt.series.length, rows = new Map(), labels = [opt.xLabel || 't [s]'], series = {}, colors = [];
    opt.series.forEach(function (s, i) {
      var name = s.name, k = 2;
      while (labels.indexOf(name) >= 0) name = s.name + ' (' + (k++) + ')';
      labels.push(name);
      colors.push(s.color || COLORS[i % COLORS.length]);
      series[name] = {stepPlot: !!s.step, strokeWidth: s.width || 1.3, drawPoints: !!opt.markers, pointSize: 2.5,
                      strokePattern: s.dash ? s.dash.split(',').map(Number) : null};
      for (var k2 = 0; k2 < s.x.length; k2++) {
        var x = s.x[k2];
        if (!finite(x)) continue;
        var row = rows.get(x);
        if (!row) { row = [x]; for (var j = 0; j < n; j++) row.push(null); rows.set(x, row); }
        row[i + 1] = finite(s.y[k2]) ? s.y[k2] : null;
      }
    });
    var data = Array.from(rows.values()).sort(function (a, b) { return a[0] - b[0]; });
    if (data.length === 0) { var empty = [0]; for (var e = 0; e < n; e++) empty.push(null); data = [empty]; }
    var link = opt.link || {plots: []};
    var band = opt.band;
    self.g = new Dygraph(div, data, {
      labels: labels, colors: colors, series: series, xlabel: opt.xLabel || 't [s]', ylabel: opt.yLabel || '',
      valueRange: opt.yRange || null, connectSeparatedPoints: true, legend: 'onmouseover', labelsSeparateLines: false,
      axisLabelFontSize: 11, xLabelHeight: 14, yLabelWidth: 14, digitsAfterDecimal: 4,
      underlayCallback: band ? function (ctx, area, g) {
        var l = g.toDomXCoord(band[0]), r = g.toDomXCoord(band[1]);
        ctx.fillStyle = 'rgba(255, 200, 0, 0.16)';
        ctx.fillRect(l, area.y, r - l, area.h);
      } : null,
      // Drag across to zoom (every linked panel follows), double-click to reset.
      zoomCallback: function (lo, hi) {
        link.plots.forEach(function (p) { if (p !== self && p.g) p.g.updateOptions({dateWindow: [lo, hi]}); });
      }
    });
    link.plots.push(self);
    if (band) html('p', 'metric window ' + fmt(band[0]) + '-' + fmt(band[1]) + ' s shaded', parent, 'band');
  }

  // A line plot. opt: {series: [{name, x, y, color, step}], xLabel, yLabel, height, markers, link}
  // link: a shared {range, full, plots} object so that stacked panels zoom together.
  function LinePlot(parent, opt) {
    if (!SVG_MODE) return new DyPlot(parent, opt);
    var self = this;
    var W = opt.width || 1200, H = opt.height || 240, M = {l: 78, r: 16, t: 10, b: 38};
    var svg = svgEl('svg', {viewBox: '0 0 ' + W + ' ' + H, 'class': 'plot', preserveAspectRatio: 'xMinYMin meet'}, parent);
    var clipId = 'clip' + (++plots);
    var defs = svgEl('defs', {}, svg);
    var clip = svgEl('clipPath', {id: clipId}, defs);
    svgEl('rect', {x: M.l, y: M.t, width: W - M.l - M.r, height: H - M.t - M.b}, clip);
    var layer = svgEl('g', {}, svg);
    var link = opt.link || {plots: []};
    if (!link.full) {
      link.full = extent(opt.series.map(function (s) { return s.x; }));
      link.range = opt.xRange ? opt.xRange.slice() : link.full.slice();
    }
    link.plots.push(self);
    function px(x, r) { return M.l + (x - r[0]) / (r[1] - r[0]) * (W - M.l - M.r); }
    function py(y, r) { return H - M.b - (y - r[0]) / (r[1] - r[0]) * (H - M.t - M.b); }
    self.draw = function () {
      while (layer.firstChild) layer.removeChild(layer.firstChild);
      var xr = link.range;
      var visible = opt.series.map(function (s) {
        var ys = [];
        for (var k = 0; k < s.x.length; k++) if (s.x[k] >= xr[0] && s.x[k] <= xr[1]) ys.push(s.y[k]);
        return ys;
      });
      var yr = opt.yRange || extent(visible);
      var pad = (yr[1] - yr[0]) * 0.06;
      yr = [yr[0] - pad, yr[1] + pad];
      var xt = ticks(xr[0], xr[1], 8), yt = ticks(yr[0], yr[1], 4);
      xt.forEach(function (t) {
        var x = px(t, xr);
        svgEl('line', {x1: x, x2: x, y1: M.t, y2: H - M.b, 'class': 'grid'}, layer);
        svgEl('text', {x: x, y: H - M.b + 14, 'text-anchor': 'middle'}, layer).textContent = tickLabel(t, xt);
      });
      yt.forEach(function (t) {
        var y = py(t, yr);
        svgEl('line', {x1: M.l, x2: W - M.r, y1: y, y2: y, 'class': 'grid'}, layer);
        svgEl('text', {x: M.l - 6, y: y + 4, 'text-anchor': 'end'}, layer).textContent = tickLabel(t, yt);
      });
      if (opt.band) {
        var b0 = Math.max(opt.band[0], xr[0]), b1 = Math.min(opt.band[1], xr[1]);
        if (b1 > b0) {
          var band = svgEl('rect', {x: px(b0, xr), y: M.t, width: px(b1, xr) - px(b0, xr), height: H - M.t - M.b,
                                    'class': 'band'}, layer);
          svgEl('title', {}, band).textContent = 'metric window ' + fmt(opt.band[0]) + '-' + fmt(opt.band[1]) + ' s';
        }
      }
      svgEl('rect', {x: M.l, y: M.t, width: W - M.l - M.r, height: H - M.t - M.b, 'class': 'axis'}, layer);
      svgEl('text', {x: (W + M.l) / 2, y: H - 4, 'text-anchor': 'middle'}, layer).textContent = opt.xLabel || 't [s]';
      svgEl('text', {x: 12, y: (H - M.b + M.t) / 2, 'text-anchor': 'middle',
                     transform: 'rotate(-90 12 ' + ((H - M.b + M.t) / 2) + ')'}, layer).textContent = opt.yLabel || '';
      opt.series.forEach(function (s, i) {
        var color = s.color || COLORS[i % COLORS.length];
        var pts = [];
        var first = 0, last = s.x.length - 1;
        while (first < last && s.x[first + 1] < xr[0]) first++;
        while (last > first && s.x[last - 1] > xr[1]) last--;
        var prevY = null;
        for (var k = first; k <= last; k++) {
          if (!finite(s.y[k])) { prevY = null; continue; }
          var X = px(s.x[k], xr).toFixed(1), Y = py(s.y[k], yr).toFixed(1);
          if (s.step && prevY !== null) pts.push(X + ',' + prevY);
          pts.push(X + ',' + Y);
          prevY = Y;
        }
        if (pts.length > 0)
          svgEl('polyline', {points: pts.join(' '), fill: 'none', stroke: color, 'stroke-width': s.width || 1.3,
                             'stroke-dasharray': s.dash || '', 'clip-path': 'url(#' + clipId + ')'}, layer);
        if (opt.markers)
          for (var m = first; m <= last; m++)
            if (finite(s.y[m]))
              svgEl('circle', {cx: px(s.x[m], xr), cy: py(s.y[m], yr), r: 2.5, fill: color,
                               'clip-path': 'url(#' + clipId + ')'}, layer);
      });
    };
    // Drag across to zoom (all linked panels), double-click to reset.
    var sel = null, x0 = 0;
    function mouseX(ev) { var b = svg.getBoundingClientRect(); return (ev.clientX - b.left) * W / b.width; }
    svg.addEventListener('mousedown', function (ev) {
      x0 = mouseX(ev);
      sel = svgEl('rect', {x: x0, y: M.t, width: 0, height: H - M.t - M.b, 'class': 'sel'}, svg);
      ev.preventDefault();
    });
    svg.addEventListener('mousemove', function (ev) {
      if (!sel) return;
      var x1 = mouseX(ev);
      sel.setAttribute('x', Math.min(x0, x1));
      sel.setAttribute('width', Math.abs(x1 - x0));
    });
    window.addEventListener('mouseup', function (ev) {
      if (!sel) return;
      var x1 = mouseX(ev);
      svg.removeChild(sel);
      sel = null;
      if (Math.abs(x1 - x0) < 5) return;
      var r = link.range;
      var a = r[0] + (Math.min(x0, x1) - M.l) / (W - M.l - M.r) * (r[1] - r[0]);
      var b = r[0] + (Math.max(x0, x1) - M.l) / (W - M.l - M.r) * (r[1] - r[0]);
      link.range = [Math.max(a, link.full[0]), Math.min(b, link.full[1])];
      link.plots.forEach(function (p) { p.draw(); });
    });
    svg.addEventListener('dblclick', function () {
      link.range = link.full.slice();
      link.plots.forEach(function (p) { p.draw(); });
    });
    self.draw();
  }

  function legend(parent, series) {
    var d = html('div', null, parent, 'legend');
    series.forEach(function (s, i) {
      var span = html('span', null, d);
      var sw = html('i', null, span);
      sw.style.background = s.color || COLORS[i % COLORS.length];
      span.appendChild(document.createTextNode(s.name));
    });
  }

  function drawRun(run, box) {
    var link = {plots: []};
    if (run.gate) new LinePlot(box, {series: [{name: 'gate', x: run.t, y: run.gate, step: true, color: '#555'}],
                                     yLabel: 'gate', height: 110, link: link, yRange: [0, 1]});
    if (run.i_A) {
      var s = [{name: 'i [A]', x: run.t, y: run.i_A, color: '#1f77b4'}];
      if (run.ref && run.controlled === 'current') s.push({name: 'reference [A]', x: run.t, y: run.ref, color: '#d62728', dash: '5,3'});
      legend(box, s);
      new LinePlot(box, {series: s, yLabel: 'current [A]', link: link});
    }
    if (run.x_m) {
      var mm = run.x_m.map(function (v) { return finite(v) ? v * 1e3 : v; });
      var p = [{name: 'x [mm]', x: run.t, y: mm, color: '#2ca02c'}];
      if (run.ref && run.controlled === 'position')
        p.push({name: 'reference [mm]', x: run.t, y: run.ref.map(function (v) { return finite(v) ? v * 1e3 : v; }),
                color: '#d62728', dash: '5,3'});
      legend(box, p);
      new LinePlot(box, {series: p, yLabel: 'position [mm]', xLabel: 't [s]', link: link});
    }
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
  // tracking error over the metric window.
  function renderOverlay(sec, box) {
    var ys = [], es = [];
    sec.series.forEach(function (s, i) {
      var color = COLORS[i % COLORS.length];
      ys.push({name: s.name, x: s.t, y: s.y, color: color});
      es.push({name: s.name, x: s.et, y: s.e, color: color});
    });
    if (sec.series.length > 0) {
      var r = sec.series[0];
      ys.push({name: 'reference', x: r.t, y: r.ref, color: '#000', dash: '5,3', width: 1});
    }
    legend(box, ys);
    new LinePlot(box, {series: ys, yLabel: sec.y_label, height: 300, band: sec.window});
    html('h3', 'Tracking error over the metric window ' + fmt(sec.window[0]) + '-' + fmt(sec.window[1]) + ' s', box);
    new LinePlot(box, {series: es, yLabel: sec.e_label, height: 260, band: sec.window});
  }

  function renderTable(sec, box) {
    if (sec.collapsed) {
      box = html('details', null, box);
      html('summary', (sec.rows || []).length + ' rows', box);
    }
    var t = html('table', null, html('div', null, box, 'scroll'));
    var tr = html('tr', null, t);
    (sec.columns || []).forEach(function (c) { html('th', c, tr); });
    (sec.rows || []).forEach(function (row, i) {
      var r = html('tr', null, t, sec.row_classes ? sec.row_classes[i] : '');
      row.forEach(function (c, j) {
        var right = sec.left ? !sec.left[j] : typeof c === 'number';
        html('td', c === null ? '' : (typeof c === 'number' ? fmt(c) : String(c)), r, right ? 'num' : '');
      });
    });
  }

  function renderScatter(sec, box) {
    var W = 1200, H = 440, M = {l: 84, r: 20, t: 14, b: 42};
    var svg = svgEl('svg', {viewBox: '0 0 ' + W + ' ' + H, 'class': 'plot'}, box);
    var clipId = 'clip' + (++plots);
    var clip = svgEl('clipPath', {id: clipId}, svgEl('defs', {}, svg));
    svgEl('rect', {x: M.l, y: M.t, width: W - M.l - M.r, height: H - M.t - M.b}, clip);
    var xs = sec.points.map(function (p) { return p.x; }), ys = sec.points.map(function (p) { return p.y; });
    var xr = extent([xs]), yr = extent([ys]);
    // A spread of a few per cent is not stretched across the plot: the axis then starts at 0.
    if (xr[0] > 0 && (xr[1] - xr[0]) < 0.05 * xr[1]) xr[0] = 0;
    var dx = (xr[1] - xr[0]) * 0.08, dy = (yr[1] - yr[0]) * 0.1;
    xr = [xr[0] - dx, xr[1] + dx]; yr = [Math.max(0, yr[0] - dy), yr[1] + dy];
    if (yr[0] >= yr[1]) yr = [yr[0] - dy, yr[1] + dy];
    function px(x) { return M.l + (x - xr[0]) / (xr[1] - xr[0]) * (W - M.l - M.r); }
    function py(y) { return H - M.b - (y - yr[0]) / (yr[1] - yr[0]) * (H - M.t - M.b); }
    var xt = ticks(xr[0], xr[1], 8), yt = ticks(yr[0], yr[1], 6);
    xt.forEach(function (t) {
      svgEl('line', {x1: px(t), x2: px(t), y1: M.t, y2: H - M.b, 'class': 'grid'}, svg);
      svgEl('text', {x: px(t), y: H - M.b + 14, 'text-anchor': 'middle'}, svg).textContent = tickLabel(t, xt);
    });
    yt.forEach(function (t) {
      svgEl('line', {x1: M.l, x2: W - M.r, y1: py(t), y2: py(t), 'class': 'grid'}, svg);
      svgEl('text', {x: M.l - 6, y: py(t) + 4, 'text-anchor': 'end'}, svg).textContent = tickLabel(t, yt);
    });
    svgEl('rect', {x: M.l, y: M.t, width: W - M.l - M.r, height: H - M.t - M.b, 'class': 'axis'}, svg);
    svgEl('text', {x: (W + M.l) / 2, y: H - 6, 'text-anchor': 'middle'}, svg).textContent = sec.x_label;
    svgEl('text', {x: 14, y: H / 2, 'text-anchor': 'middle', transform: 'rotate(-90 14 ' + H / 2 + ')'}, svg).textContent = sec.y_label;
    var front = sec.points.filter(function (p) { return p.front; }).sort(function (a, b) { return a.x - b.x; });
    if (front.length > 1)
      svgEl('polyline', {points: front.map(function (p) { return px(p.x) + ',' + py(p.y); }).join(' '),
                         fill: 'none', stroke: '#d62728', 'stroke-width': 1.5, 'stroke-dasharray': '6,3'}, svg);
    var placed = [];  // label boxes already drawn: a new label moves down until it overlaps none
    function place(x, y, w, right) {
      var x0 = right ? x - w : x, h = 13;
      for (var tries = 0; tries < 30; tries++) {
        var hit = placed.some(function (b) { return x0 < b.x + b.w && b.x < x0 + w && y - h < b.y && b.y - h < y; });
        if (!hit) break;
        y += h;
      }
      placed.push({x: x0, y: y, w: w});
      return y;
    }
    sec.points.slice().sort(function (a, b) { return a.y - b.y; }).reverse().forEach(function (p) {
      var color = p.front ? '#d62728' : '#1f77b4';
      var clipped = {stroke: color, 'clip-path': 'url(#' + clipId + ')'};
      if (p.y_err > 0) svgEl('line', Object.assign({x1: px(p.x), x2: px(p.x), y1: py(p.y - p.y_err), y2: py(p.y + p.y_err)}, clipped), svg);
      if (p.x_err > 0) svgEl('line', Object.assign({x1: px(p.x - p.x_err), x2: px(p.x + p.x_err), y1: py(p.y), y2: py(p.y)}, clipped), svg);
      var c = svgEl('circle', {cx: px(p.x), cy: py(p.y), r: p.front ? 6 : 4.5, fill: color}, svg);
      svgEl('title', {}, c).textContent = p.label + ': ' + sec.x_label + ' ' + fmt(p.x) + ', ' + sec.y_label + ' ' + fmt(p.y);
      var right = px(p.x) > W * 0.7;
      var ly = place(px(p.x) + (right ? -8 : 8), py(p.y) - 6, 7 * p.label.length, right);
      svgEl('text', {x: px(p.x) + (right ? -8 : 8), y: ly, 'text-anchor': right ? 'end' : 'start'}, svg).textContent = p.label;
    });
    legend(box, [{name: 'Pareto front (not dominated in both)', color: '#d62728'}, {name: 'dominated', color: '#1f77b4'}]);
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

  function renderLines(sec, box) {
    var series = (sec.series || []).map(function (s) { return {name: s.name, x: s.x, y: s.y, dash: s.dash, width: s.width}; });
    legend(box, series);
    new LinePlot(box, {series: series, xLabel: sec.x_label, yLabel: sec.y_label, height: 340, markers: !!sec.markers});
  }

  var data = JSON.parse(document.getElementById('vb-data').textContent);
  var root = document.getElementById('vb-report');
  var renderers = {traces: renderTraces, table: renderTable, scatter: renderScatter, bars: renderBars, lines: renderLines,
                   meta: renderMeta, overlay: renderOverlay,
                   note: function (sec, box) { html('p', sec.text, box, 'note ' + (sec['class'] || '')); }};
  var count = 0;
  data.sections.forEach(function (sec) {
    var box = html('section', null, root);
    if (sec.title && sec.kind !== 'table') html('h2', sec.title, box);
    if (sec.title && sec.kind === 'table') html('h2', sec.title, box);
    var r = renderers[sec.kind];
    if (!r) throw new Error('unknown section kind ' + sec.kind);
    r(sec, box);
    count++;
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
  Json data = {{"title", title}, {"sections", sections.is_array() ? sections : Json::array()}};
  std::string out;
  out += "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>";
  out += EscapeHtml(title);
  out += "</title>\n<link rel=\"icon\" href=\"data:,\">\n<style>";
  out += kCss;
  out += "</style>\n";
  // dygraphs as Debian ships it (MIT licence comment kept), without its source-map line: nothing to fetch.
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
