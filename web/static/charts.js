// valvebench web dashboard (docs/web.md "Charts"): every chart of the Compare, Run and Diagnosis pages.
// Time series and scatters are Debian's dygraphs (the library the HTML report inlines); heat maps and bar
// charts are SVG. Each chart: axes with SI-prefixed units (format.js, the CLI's prefix table), its legend below
// it (never over the curves), one colour per name for the whole page, and PNG and SVG downloads.
'use strict';

const VBCharts = (() => {
  // The HTML report's palette (report/page.cc), in the same order.
  const PALETTE = ['#1f77b4', '#d62728', '#2ca02c', '#ff7f0e', '#9467bd', '#8c564b', '#e377c2', '#17becf', '#7f7f7f',
    '#bcbd22'];
  const NS = 'http://www.w3.org/2000/svg';
  const Y_AXIS_WIDTH = 64;  // every chart's left margin: stacked time axes line up
  const RIGHT_GAP = 16;
  const X_TICK_PX = 100, Y_TICK_PX = 45;  // about one tick per this many pixels
  const BAND_FILL = 'rgba(255, 200, 0, 0.16)';

  // One colour per name (a law, a case, a run) for every chart of a page. A law has its own colour on every
  // page (LAW_COLORS: PI is green in every comparison); other names take the palette's next free colour in
  // order of first appearance, and past the palette's ten, dashes as well.
  const LAW_COLORS = {fuzzy_current: PALETTE[0], predictive_current: PALETTE[1], pi_current: PALETTE[2],
    hysteresis_current: PALETTE[3], cascade_pi_position: PALETTE[4], sliding_mode_position: PALETTE[5],
    peak_and_hold: PALETTE[6], dither_pwm: PALETTE[7], open_loop_pwm: PALETTE[8]};
  const DASHES = [[6, 3], [2, 2], [8, 3, 2, 3]];
  class Palette {
    constructor() { this.map = new Map(); this.over = 0; }
    // `name` drawn in the colour of the law `controller` (when the page knows that law's colour).
    fixLaw(name, controller) {
      if (!this.map.has(name) && LAW_COLORS[controller]) this.map.set(name, {color: LAW_COLORS[controller], dash: null});
    }
    entry(name) {
      if (!this.map.has(name)) {
        const used = new Set(Array.from(this.map.values()).filter((e) => !e.dash).map((e) => e.color));
        // The first colour no name has yet (before: the k-th free one of a shrinking list, which skipped colours).
        const free = PALETTE.filter((c) => !used.has(c));
        if (free.length) this.map.set(name, {color: free[0], dash: null});
        else {
          const k = this.over++;
          this.map.set(name, {color: PALETTE[k % PALETTE.length], dash: DASHES[Math.floor(k / PALETTE.length) % DASHES.length]});
        }
      }
      return this.map.get(name);
    }
    colorOf(name) { return this.entry(name).color; }
    dashOf(name) { return this.entry(name).dash; }
  }

  function h(tag, attrs, ...children) {
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
  function s(tag, attrs, parent) {
    const e = document.createElementNS(NS, tag);
    for (const [k, v] of Object.entries(attrs || {})) e.setAttribute(k, v);
    if (parent) parent.appendChild(e);
    return e;
  }
  const finite = (v) => typeof v === 'number' && isFinite(v);
  const esc = (t) => String(t).replace(/[&<>"]/g, (c) => ({'&': '&amp;', '<': '&lt;', '>': '&gt;', '"': '&quot;'}[c]));
  // `prefixed`: VBFormat.prefixFor's result (its `unit` is the prefixed unit: mm^2, mg/s).
  function axisTitle(label, prefixed, unit) {
    if (!unit) return label;
    return label + ' [' + (prefixed && prefixed.unit ? prefixed.unit : unit) + ']';
  }
  function slug(t) { return String(t).toLowerCase().replace(/[^a-z0-9]+/g, '-').replace(/^-|-$/g, '') || 'chart'; }

  // ---- downloads: SVG as drawn; PNG rasterised from that SVG at twice the size
  function download(name, blob) {
    const a = h('a', {href: URL.createObjectURL(blob), download: name});
    document.body.append(a);
    a.click();
    setTimeout(() => { URL.revokeObjectURL(a.href); a.remove(); }, 1000);
  }
  function svgText(svg) {
    if (!svg.getAttribute('xmlns')) svg.setAttribute('xmlns', NS);
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + new XMLSerializer().serializeToString(svg);
  }
  function pngOf(svg) {
    return new Promise((resolve, reject) => {
      const w = Number(svg.getAttribute('width')), hh = Number(svg.getAttribute('height'));
      const img = new Image();
      img.onload = () => {
        const c = document.createElement('canvas');
        c.width = 2 * w; c.height = 2 * hh;
        const ctx = c.getContext('2d');
        ctx.scale(2, 2);
        ctx.fillStyle = '#fff';
        ctx.fillRect(0, 0, w, hh);
        ctx.drawImage(img, 0, 0, w, hh);
        c.toBlob((b) => (b ? resolve(b) : reject(new Error('PNG: the browser made no image'))), 'image/png');
      };
      img.onerror = () => reject(new Error('PNG: the SVG did not load'));
      img.src = 'data:image/svg+xml;charset=utf-8,' + encodeURIComponent(svgText(svg));
    });
  }
  // The toolbar of a chart: its title and the two downloads (makeSvg() gives a standalone <svg>).
  function frame(title, makeSvg, extraClass) {
    const box = h('figure', {class: 'vb-chart' + (extraClass ? ' ' + extraClass : '')});
    const name = slug(title);
    const bar = h('figcaption', {class: 'vb-chart-bar'}, h('span', {class: 'vb-chart-title', text: title}),
      h('span', {class: 'vb-chart-dl'},
        h('button', {type: 'button', class: 'link dl-svg', title: 'download this chart as SVG',
          onclick: () => download(name + '.svg', new Blob([svgText(makeSvg())], {type: 'image/svg+xml'})), text: 'SVG'}),
        h('button', {type: 'button', class: 'link dl-png', title: 'download this chart as PNG',
          onclick: () => pngOf(makeSvg()).then((b) => download(name + '.png', b)).catch((e) => alert(e.message)), text: 'PNG'})));
    box.append(bar);
    return box;
  }

  // A legend below a chart: a swatch per series, a link where the series has one (a run, a case's runs).
  function legend(series) {
    return h('div', {class: 'vb-legend'}, series.filter((x) => !x.hideInLegend).map((x) =>
      h('span', {class: 'vb-legend-item'}, h('i', {style: x.dash ? 'background:repeating-linear-gradient(90deg,' + x.color + ' 0 ' + x.dash[0] + 'px,transparent ' +
        x.dash[0] + 'px ' + (x.dash[0] + x.dash[1]) + 'px);height:3px' : 'background:' + x.color}),
        x.href ? h('a', {href: x.href, text: x.name}) : x.name)));
  }

  // ---- dygraphs charts: time series (lines, steps) and scatters (points with labels, a front)
  // opts: {title, x: {label, unit, range}, y: {label, unit, range, logic}, series: [{name, color, step, points,
  //   width, dash, href, hideInLegend}], rows: [[x, y1, y2, ...]], height, labels: [{x, y, text, color}] (point
  //   labels), pad (fraction of the data range added around a scatter), band ([x0, x1] shaded), onZoom(lo, hi)}
  // Returns {g, box, opts, setRows(rows)} (g null when the page went away).
  function plot(parent, opts, cleanups) {
    const plotDiv = h('div', {class: 'vb-plot', style: 'height:' + (opts.height || 240) + 'px'});
    const hover = h('div', {class: 'vb-hover muted'});
    const c = {g: null, opts, rows: opts.rows};
    const box = frame(opts.title, () => toSvg(c), opts.class);
    box.append(plotDiv, hover, legend(opts.series));
    parent.append(box);
    c.box = box;
    if (!box.isConnected) return c;
    const labels = [opts.x.label].concat(opts.series.map((x) => x.name));
    const series = {};
    for (const x of opts.series)
      series[x.name] = {color: x.color, stepPlot: !!x.step, drawPoints: !!x.points, pointSize: x.points ? 5 : 1,
        strokeWidth: x.width === undefined ? 1.3 : x.width, strokePattern: x.dash || null,
        connectSeparatedPoints: !!x.connect, highlightCircleSize: x.points ? 6 : 3};
    const tickerFor = (unit, logic, spacing) => (lo, hi, pixels) => {
      if (logic) return [{v: 0, label: '0 (off)'}, {v: 1, label: '1 (on)'}];
      return VBFormat.ticks(lo, hi, Math.max(2, Math.floor(pixels / spacing)), unit).ticks;
    };
    const rows = opts.rows.length ? opts.rows : [[0].concat(opts.series.map(() => null))];
    const dateWindow = opts.x.range || (opts.pad ? padded(rows.map((r) => r[0]), opts.pad) : null);
    const valueRange = opts.y.logic ? [-0.1, 1.15] : opts.y.range ||
      (opts.pad ? padded(rows.flatMap((r) => r.slice(1)), opts.pad) : null);
    c.g = new Dygraph(plotDiv, rows, {
      labels, series, colors: opts.series.map((x) => x.color), legend: 'onmouseover', labelsDiv: hover,
      labelsSeparateLines: false, showLabelsOnHighlight: true, xlabel: opts.x.label, ylabel: opts.y.label,
      dateWindow, valueRange, connectSeparatedPoints: false, animatedZooms: false, rightGap: RIGHT_GAP,
      drawPoints: false, strokeWidth: 1.3, xRangePad: opts.pad ? 0 : 0, yRangePad: opts.pad ? 0 : 6,
      axes: {x: {ticker: tickerFor(opts.x.unit, false, X_TICK_PX), axisLabelWidth: 70},
        y: {ticker: tickerFor(opts.y.unit, opts.y.logic, Y_TICK_PX), axisLabelWidth: Y_AXIS_WIDTH}},
      valueFormatter: (v, o, name) => (name === opts.x.label ? VBFormat.value(v, opts.x.unit) : VBFormat.value(v, opts.y.unit)),
      zoomCallback: opts.onZoom ? (lo, hi) => opts.onZoom(lo, hi) : null,
      // opts.band [x0, x1]: an x interval shaded (a metric window).
      underlayCallback: opts.band ? (ctx, area, g) => {
        const l = g.toDomXCoord(opts.band[0]), r = g.toDomXCoord(opts.band[1]);
        ctx.fillStyle = BAND_FILL;
        ctx.fillRect(l, area.y, r - l, area.h);
      } : null,
      drawCallback: (g) => {
        // The axis titles carry the prefix the ticks are in.
        const xr = g.xAxisRange(), yr = g.yAxisRange();
        const px = VBFormat.prefixFor(Math.max(Math.abs(xr[0]), Math.abs(xr[1])), opts.x.unit);
        const py = VBFormat.prefixFor(Math.max(Math.abs(yr[0]), Math.abs(yr[1])), opts.y.unit);
        const xl = plotDiv.querySelector('.dygraph-xlabel'), yl = plotDiv.querySelector('.dygraph-ylabel');
        if (xl) xl.textContent = axisTitle(opts.x.label, px, opts.x.unit);
        if (yl) yl.textContent = opts.y.logic ? opts.y.label : axisTitle(opts.y.label, py, opts.y.unit);
        placeLabels(c, g);
      },
    });
    plotDiv.vbChart = c;  // for the browser test (tests/web/browser_test.py) and the downloads
    c.setRows = (r) => { c.rows = r; c.g.updateOptions({file: r.length ? r : rows}); };
    if (cleanups) cleanups.push(() => c.g.destroy());
    return c;
  }
  function padded(values, frac) {
    const v = values.filter(finite);
    if (!v.length) return null;
    let lo = Math.min(...v), hi = Math.max(...v);
    if (lo === hi) { const d = Math.abs(lo) * 0.1 || 1; lo -= d; hi += d; }
    const d = (hi - lo) * frac;
    return [lo - d, hi + d];
  }
  // Point labels as elements over the plot, each beside its point and kept inside the plot area (to the left
  // of the point when it would cross the right edge, under it when it would cross the top).
  function placeLabels(c, g) {
    const div = g ? g.graphDiv : null;
    if (!div || !c.opts.labels) return;
    for (const e of div.querySelectorAll('.vb-point-label')) e.remove();
    const a = g.getArea();
    const placed = [];  // boxes taken by labels and points: a label goes where it covers neither
    const pts = c.opts.labels.map((L) => g.toDomCoords(L.x, L.y));
    for (const [x, y] of pts) if (finite(x) && finite(y)) placed.push([x - 4, y - 4, x + 4, y + 4]);
    const hits = (b) => placed.some((p) => b[0] < p[2] && b[2] > p[0] && b[1] < p[3] && b[3] > p[1]);
    c.opts.labels.forEach((L, k) => {
      const [x, y] = pts[k];
      if (!finite(x) || !finite(y) || x < a.x - 1 || x > a.x + a.w + 1 || y < a.y - 1 || y > a.y + a.h + 1) return;
      const e = h('div', {class: 'vb-point-label', text: L.text, style: 'color:' + (L.color || '#333')});
      div.append(e);
      const w = e.offsetWidth, hh = e.offsetHeight;
      const clampBox = (left, top) => {
        left = Math.min(Math.max(left, a.x + 2), a.x + a.w - w - 2);
        top = Math.min(Math.max(top, a.y + 1), a.y + a.h - hh - 1);
        return [left, top, left + w, top + hh];
      };
      // Right, left, above, below, then further out, each kept inside the plot area.
      const tries = [];
      for (const d of [0, 1, 2, 3])
        tries.push([x + 7, y - hh / 2 - d * hh], [x - 7 - w, y - hh / 2 - d * hh], [x + 7, y - hh / 2 + d * hh],
          [x - 7 - w, y - hh / 2 + d * hh], [x - w / 2, y - hh - 5 - d * hh], [x - w / 2, y + 5 + d * hh]);
      let box = null;
      for (const [l, t] of tries) { const b = clampBox(l, t); if (!hits(b)) { box = b; break; } }
      if (!box) box = clampBox(x + 7, y - hh / 2);
      placed.push(box);
      e.style.left = box[0] + 'px';
      e.style.top = box[1] + 'px';
    });
  }

  // The chart as a standalone SVG: what the canvas shows (grid, ticks, series in the visible window, point
  // labels, axis titles) and the legend under it.
  function toSvg(c) {
    const g = c.g, o = c.opts;
    const W = g.graphDiv.clientWidth, H = g.graphDiv.clientHeight;
    const items = o.series.filter((x) => !x.hideInLegend);
    const perRow = Math.max(1, Math.floor(W / 220)), legendH = 18 * Math.ceil(items.length / perRow) + 8;
    const svg = s('svg', {xmlns: NS, width: W, height: H + legendH + 24, viewBox: '0 0 ' + W + ' ' + (H + legendH + 24),
      'font-family': 'system-ui, sans-serif', 'font-size': 11});
    s('rect', {x: 0, y: 0, width: W, height: H + legendH + 24, fill: '#fff'}, svg);
    s('text', {x: 4, y: 15, 'font-size': 13, 'font-weight': 600}, svg).textContent = o.title;
    const root = s('g', {transform: 'translate(0, 24)'}, svg);
    const a = g.getArea(), xr = g.xAxisRange(), yr = g.yAxisRange();
    const X = (v) => g.toDomXCoord(v), Y = (v) => g.toDomYCoord(v);
    const clip = 'clip' + Math.random().toString(36).slice(2);
    s('rect', {x: a.x, y: a.y, width: a.w, height: a.h}, s('clipPath', {id: clip}, s('defs', {}, root)));
    const xt = VBFormat.ticks(xr[0], xr[1], Math.max(2, Math.floor(a.w / X_TICK_PX)), o.x.unit);
    const yt = o.y.logic ? {ticks: [{v: 0, label: '0 (off)'}, {v: 1, label: '1 (on)'}], symbol: ''}
      : VBFormat.ticks(yr[0], yr[1], Math.max(2, Math.floor(a.h / Y_TICK_PX)), o.y.unit);
    for (const t of xt.ticks) {
      s('line', {x1: X(t.v), x2: X(t.v), y1: a.y, y2: a.y + a.h, stroke: '#e6e6e6'}, root);
      s('text', {x: X(t.v), y: a.y + a.h + 14, 'text-anchor': 'middle', fill: '#333'}, root).textContent = t.label;
    }
    for (const t of yt.ticks) {
      s('line', {x1: a.x, x2: a.x + a.w, y1: Y(t.v), y2: Y(t.v), stroke: '#e6e6e6'}, root);
      s('text', {x: a.x - 5, y: Y(t.v) + 4, 'text-anchor': 'end', fill: '#333'}, root).textContent = t.label;
    }
    if (o.band) {
      const l = Math.max(a.x, X(o.band[0])), r = Math.min(a.x + a.w, X(o.band[1]));
      if (r > l) s('rect', {x: l, y: a.y, width: r - l, height: a.h, fill: BAND_FILL, class: 'band'}, root);
    }
    s('rect', {x: a.x, y: a.y, width: a.w, height: a.h, fill: 'none', stroke: '#999'}, root);
    const layer = s('g', {'clip-path': 'url(#' + clip + ')'}, root);
    o.series.forEach((x, k) => {
      const pts = [];
      let prev = null, run = [];
      const flush = () => { if (run.length > 1 && x.width !== 0) pts.push(run.join(' ')); run = []; };
      for (const r of c.rows) {
        const v = r[k + 1];
        if (!finite(v) || !finite(r[0])) { if (!x.connect) { flush(); prev = null; } continue; }
        if (r[0] < xr[0] - (xr[1] - xr[0]) || r[0] > xr[1] + (xr[1] - xr[0])) continue;
        const px = X(r[0]).toFixed(1), py = Y(v).toFixed(1);
        if (x.step && prev !== null) run.push(px + ',' + prev);
        run.push(px + ',' + py);
        prev = py;
        if (x.points) s('circle', {cx: px, cy: py, r: 4, fill: x.color}, layer);
      }
      flush();
      for (const p of pts)
        s('polyline', {points: p, fill: 'none', stroke: x.color, 'stroke-width': x.width === undefined ? 1.3 : x.width,
          'stroke-dasharray': x.dash ? x.dash.join(',') : 'none'}, layer);
    });
    const divBox = g.graphDiv.getBoundingClientRect();
    for (const e of g.graphDiv.querySelectorAll('.vb-point-label')) {
      const b = e.getBoundingClientRect();
      s('text', {x: b.left - divBox.left, y: b.bottom - divBox.top - 3, fill: e.style.color || '#333'}, root).textContent = e.textContent;
    }
    const xl = g.graphDiv.querySelector('.dygraph-xlabel'), yl = g.graphDiv.querySelector('.dygraph-ylabel');
    s('text', {x: a.x + a.w / 2, y: H - 4, 'text-anchor': 'middle', 'font-size': 12}, root).textContent = xl ? xl.textContent : o.x.label;
    s('text', {x: 0, y: 0, 'text-anchor': 'middle', 'font-size': 12,
      transform: 'translate(13,' + (a.y + a.h / 2) + ') rotate(-90)'}, root).textContent = yl ? yl.textContent : o.y.label;
    items.forEach((x, k) => {
      const col = k % perRow, row = Math.floor(k / perRow);
      const lx = 8 + col * 220, ly = H + 14 + row * 18;
      s('rect', {x: lx, y: ly - 4, width: 14, height: 3, fill: x.color}, root);
      s('text', {x: lx + 18, y: ly}, root).textContent = x.name.length > 34 ? x.name.slice(0, 33) + '…' : x.name;
    });
    return svg;
  }

  // Charts whose time axes move together: a zoom on one zooms all; a double-click resets all.
  function linkTime(charts) {
    charts = charts.filter((c) => c.g);  // a page left while loading drew nothing
    let busy = false;
    for (const c of charts) {
      const prev = c.opts.onZoom;
      c.g.updateOptions({zoomCallback: (lo, hi) => {
        if (busy) return;
        busy = true;
        for (const o of charts) if (o !== c) o.g.updateOptions({dateWindow: [lo, hi]});
        busy = false;
        if (prev) prev(lo, hi);
      }});
    }
  }

  // ---- SVG charts: a heat map over two sweep axes, grouped bars
  // A heat map: cells at (x, y) coloured by z (viridis-like ramp), the value written in each cell.
  // opts: {title, x: {label, values, fmt}, y: {label, values, fmt}, z: {label, get(x, y) -> number|null, fmt},
  //   hrefOf(x, y)}
  function heatmap(parent, opts) {
    const make = () => {
      const nx = opts.x.values.length, ny = opts.y.values.length;
      const cw = Math.max(16, Math.min(56, Math.floor(440 / nx))), ch = Math.max(22, Math.min(48, Math.floor(220 / ny)));
      const L = 90, T = 10, W = L + nx * cw + 150, H = T + ny * ch + 50;
      const svg = s('svg', {xmlns: NS, width: W, height: H, viewBox: '0 0 ' + W + ' ' + H, class: 'vb-heatmap',
        'font-family': 'system-ui, sans-serif', 'font-size': 11});
      s('rect', {x: 0, y: 0, width: W, height: H, fill: '#fff', class: 'vb-bg'}, svg);
      const zs = [];
      for (const x of opts.x.values) for (const y of opts.y.values) { const z = opts.z.get(x, y); if (finite(z)) zs.push(z); }
      const lo = Math.min(...zs), hi = Math.max(...zs);
      const color = (z) => ramp(hi > lo ? (z - lo) / (hi - lo) : 0.5);
      opts.y.values.forEach((y, j) => {
        const ty = T + (ny - 1 - j) * ch;
        s('text', {x: L - 6, y: ty + ch / 2 + 4, 'text-anchor': 'end'}, svg).textContent = opts.y.fmt(y);
        opts.x.values.forEach((x, i) => {
          const z = opts.z.get(x, y);
          const r = s('rect', {x: L + i * cw, y: ty, width: cw - 1, height: ch - 1, fill: finite(z) ? color(z) : '#eee'}, svg);
          s('title', {}, r).textContent = opts.x.label + ' ' + opts.x.fmt(x) + ', ' + opts.y.label + ' ' + opts.y.fmt(y) +
            ': ' + (finite(z) ? opts.z.fmt(z) : 'no value');
          if (finite(z) && cw >= 34)
            s('text', {x: L + i * cw + cw / 2, y: ty + ch / 2 + 4, 'text-anchor': 'middle', 'font-size': 10, class: 'vb-cell',
              fill: (hi > lo ? (z - lo) / (hi - lo) : 0.5) > 0.55 ? '#000' : '#fff'}, svg).textContent = opts.z.fmt(z);
        });
      });
      const step = Math.max(1, Math.ceil(nx * 34 / (nx * cw)));
      opts.x.values.forEach((x, i) => {
        if (i % step === 0)
          s('text', {x: L + i * cw + cw / 2, y: T + ny * ch + 14, 'text-anchor': 'middle'}, svg).textContent = opts.x.fmt(x);
      });
      s('text', {x: L + nx * cw / 2, y: T + ny * ch + 34, 'text-anchor': 'middle', 'font-size': 12}, svg).textContent = opts.x.label;
      s('text', {x: 0, y: 0, 'text-anchor': 'middle', 'font-size': 12,
        transform: 'translate(12,' + (T + ny * ch / 2) + ') rotate(-90)'}, svg).textContent = opts.y.label;
      // The colour scale.
      const sx = L + nx * cw + 24;
      for (let k = 0; k < 40; k++)
        s('rect', {x: sx, y: T + (39 - k) * (ny * ch / 40), width: 14, height: ny * ch / 40 + 0.5, fill: ramp(k / 39)}, svg);
      s('text', {x: sx + 18, y: T + 10}, svg).textContent = finite(hi) ? opts.z.fmt(hi) : '';
      s('text', {x: sx + 18, y: T + ny * ch}, svg).textContent = finite(lo) ? opts.z.fmt(lo) : '';
      s('text', {x: sx + 18, y: T + ny * ch / 2 + 4}, svg).textContent = opts.z.label;
      return svg;
    };
    const box = frame(opts.title, make);
    box.append(h('div', {class: 'vb-svg-wrap'}, make()));
    parent.append(box);
    return box;
  }
  // Viridis, five stops interpolated.
  function ramp(t) {
    const stops = [[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]];
    t = Math.max(0, Math.min(1, t)) * (stops.length - 1);
    const k = Math.min(stops.length - 2, Math.floor(t)), f = t - k;
    const c = stops[k].map((v, i) => Math.round(v + (stops[k + 1][i] - v) * f));
    return 'rgb(' + c.join(',') + ')';
  }

  // Grouped horizontal bars: one group per category, one bar per series.
  // opts: {title, categories: [name], series: [{name, color, values: [number|null]}], unit, label}
  function bars(parent, opts) {
    const make = () => {
      const all = opts.series.flatMap((x) => x.values).filter(finite);
      const max = Math.max(...all, 0);
      const p = VBFormat.prefixFor(max, opts.unit);
      const L = 170, R = 90, bh = 14, gap = 10, T = 8;
      const W = 760, nb = opts.series.length;
      const H = T + opts.categories.length * (nb * bh + gap) + 54;
      const svg = s('svg', {xmlns: NS, width: W, height: H, viewBox: '0 0 ' + W + ' ' + H, class: 'vb-bars',
        'font-family': 'system-ui, sans-serif', 'font-size': 11});
      s('rect', {x: 0, y: 0, width: W, height: H, fill: '#fff', class: 'vb-bg'}, svg);
      const X = (v) => L + (max > 0 ? v / max : 0) * (W - L - R);
      const t = VBFormat.ticks(0, max || 1, 5, opts.unit);
      const bottom = T + opts.categories.length * (nb * bh + gap);
      for (const k of t.ticks) {
        s('line', {x1: X(k.v), x2: X(k.v), y1: T, y2: bottom, stroke: '#e6e6e6'}, svg);
        s('text', {x: X(k.v), y: bottom + 13, 'text-anchor': 'middle'}, svg).textContent = k.label;
      }
      s('text', {x: L + (W - L - R) / 2, y: bottom + 28, 'text-anchor': 'middle', 'font-size': 12}, svg).textContent =
        axisTitle(opts.label, t, opts.unit);
      opts.categories.forEach((cat, i) => {
        const y0 = T + i * (nb * bh + gap);
        s('text', {x: L - 6, y: y0 + nb * bh / 2 + 4, 'text-anchor': 'end'}, svg).textContent = cat;
        opts.series.forEach((x, j) => {
          const v = x.values[i];
          if (!finite(v)) return;
          s('rect', {x: L, y: y0 + j * bh, width: Math.max(0.5, X(v) - L), height: bh - 2, fill: x.color, class: 'vb-bar'}, svg);
          s('text', {x: X(v) + 4, y: y0 + j * bh + bh - 4}, svg).textContent = VBFormat.value(v, opts.unit);
        });
      });
      opts.series.forEach((x, j) => {
        s('rect', {x: L + j * 180, y: bottom + 38, width: 14, height: 8, fill: x.color}, svg);
        s('text', {x: L + j * 180 + 18, y: bottom + 46}, svg).textContent = x.name;
      });
      return svg;
    };
    const box = frame(opts.title, make);
    box.append(h('div', {class: 'vb-svg-wrap'}, make()));
    parent.append(box);
    return box;
  }

  // Gaps in a live stream (issue 37: a chart must not invent data). step(t) takes each new sample's time in
  // order and returns the time at which to break the lines (a row of nulls) when the interval before t is a
  // hole, else null. A hole: an interval over 5x the stream's typical one (the median of the last 64) and over
  // 20 ms; the first 8 intervals only learn. gaps and missing_s count what was not received.
  function holes() {
    const recent = [];
    const st = {gaps: 0, missing_s: 0, last: -Infinity};
    st.step = (t) => {
      const last = st.last;
      st.last = t;
      if (!Number.isFinite(last)) return null;
      const dt = t - last;
      const typical = recent.length >= 8 ? [...recent].sort((a, b) => a - b)[recent.length >> 1] : null;
      if (typical !== null && dt > 5 * typical && dt > 0.02) {
        st.gaps++;
        st.missing_s += dt - typical;
        return last + typical;
      }
      recent.push(dt);
      if (recent.length > 64) recent.shift();
      return null;
    };
    return st;
  }

  // A y range never narrower than 2 % of the largest magnitude in `rows` ([x, y1, y2, ...]) nor than `floor`
  // (issue 37: a flat 500 mA hold autoscaled onto 1e-12 A of rounding, ticks "500.00000 0002"); null when the
  // data span more (the chart's own range).
  function minSpanRange(rows, floor) {
    let lo = Infinity, hi = -Infinity;
    for (const r of rows) for (let k = 1; k < r.length; k++) if (Number.isFinite(r[k])) { lo = Math.min(lo, r[k]); hi = Math.max(hi, r[k]); }
    if (!(hi >= lo)) return null;
    const span = Math.max(0.02 * Math.max(Math.abs(lo), Math.abs(hi)), floor);
    if (hi - lo >= span) return null;
    const mid = (hi + lo) / 2;
    return [mid - span / 2, mid + span / 2];
  }

  return {Palette, PALETTE, plot, linkTime, heatmap, bars, legend, toSvg, pngOf, svgText, esc, el: h, holes, minSpanRange};
})();
