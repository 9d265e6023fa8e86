#!/usr/bin/python3
"""The web dashboard in a real browser (docs/web.md): Debian's chromium, driven by chromium-driver through
python3-selenium, against a real valvebench-server on loopback. Logs in with a token, submits a run, sees live
samples arrive, cancels it, opens a comparison and a run's traces, checks that no page logs a console error or
overflows horizontally at 1400 px and 1024 px, and that a viewer token cannot submit. All traffic but loopback
goes to a dead proxy, so a page that needed the network would fail here.

Usage: browser_test.py SERVER_BINARY EXAMPLES_DIR WORK_DIR [SCREENSHOT_DIR]
Exit 0 pass, 1 fail, 77 skipped (chromium, chromedriver or selenium missing)."""
import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
import time
import urllib.error
import urllib.request

server_bin, examples_dir, work = sys.argv[1:4]
shots = sys.argv[4] if len(sys.argv) > 4 else work

CHROMIUM, DRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"
missing = [p for p in (CHROMIUM, DRIVER) if not os.path.exists(p)]
try:
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait
    from selenium.common.exceptions import NoSuchElementException, StaleElementReferenceException
except ImportError:
    missing.append("python3-selenium")
if missing:
    print("SKIP: the browser test needs %s (apt-get install chromium chromium-driver python3-selenium)"
          % ", ".join(missing))
    sys.exit(77)

OPERATOR, VIEWER, OPERATOR2 = "web-operator-token", "web-viewer-token", "web-operator2-token"
shutil.rmtree(work, ignore_errors=True)
os.makedirs(work)
os.makedirs(shots, exist_ok=True)


def sha(t):
    return hashlib.sha256(t.encode()).hexdigest()


# A regression night at start (--run-night-now) whose PI law got worse than the baseline: a regressed night for
# the Nights page (as tests/integration/nights_test.cc makes one).
suites = os.path.abspath(os.path.join(examples_dir, "suites"))
shutil.copy(os.path.join(suites, "ci.json"), work)
with open(os.path.join(suites, "ci-current-hold.json")) as f:
    hold = f.read()
law = hold.find('"pi_current": {}', hold.find('"name": "pi"'))
assert law >= 0, "examples/suites/ci-current-hold.json changed: no pi variant"
with open(os.path.join(work, "ci-current-hold.json"), "w") as f:
    # The proportional gain cut tenfold (a tenfold smaller integral gain improves the hold's exact RMSE since
    # issue 37; tests/integration/regress_ci_test.cc).
    f.write(hold[:law] + '"pi_current": {"kp_V_per_A": 37.7}' + hold[law + len('"pi_current": {}'):])
config = {"listen_address": "127.0.0.1:0", "database_path": "runs.db",
          "nights": {"cron": "0 2 * * *", "suite_file": "ci.json",
                     "baseline_file": os.path.join(suites, "ci-baseline.json")},
          # Both checked before each night (the Bench health page, and a cause for every regressed case whichever
          # bench ran it): a switch-on run at two supplies and two pressures.
          "benches": [{"name": "emu-1", "kind": "emulated", "model": {"preset": "taghizadeh2009"}, "current_noise_A": 0.002,
                       "health": {"supply_V": [24, 20], "supply_pressure_Pa": [100000, 400000]}},
                      {"name": "emu-2", "kind": "emulated", "model": {"preset": "taghizadeh2009"}, "current_noise_A": 0.002,
                       "health": {"supply_V": [24, 20], "supply_pressure_Pa": [100000, 400000]}}],
          "tokens": [{"user": "olga", "role": "operator", "token_sha256": sha(OPERATOR)},
                     {"user": "vic", "role": "viewer", "token_sha256": sha(VIEWER)},
                     {"user": "oscar", "role": "operator", "token_sha256": sha(OPERATOR2)}],
          "web": {"listen_address": "127.0.0.1:0"}}
with open(os.path.join(work, "server.json"), "w") as f:
    json.dump(config, f)
log = open(os.path.join(work, "server.log"), "w+")
# Three nights lived at start (--simulate-nights 3, docs/track.md): each regressed (the PI law got worse), each with
# emu-1's health check identified and tracked.
NIGHTS = 3
proc = subprocess.Popen([server_bin, "--config", os.path.join(work, "server.json"), "--simulate-nights", str(NIGHTS)], stderr=log,
                        stdout=subprocess.DEVNULL)
failures = []
driver = None
t_start = time.time()


def check(name, cond, detail=""):
    print(("ok   " if cond else "FAIL ") + name + ("" if cond else ": " + str(detail)[:600]))
    if not cond:
        failures.append(name)


def api(method, path, token, body=None):
    req = urllib.request.Request(base + path, method=method, headers={"Authorization": "Bearer " + token,
                                                                      "Content-Type": "application/json"},
                                 data=None if body is None else json.dumps(body).encode())
    with urllib.request.urlopen(req, timeout=10) as r:
        return json.loads(r.read() or b"{}")


def wait(cond, timeout=20, what="condition"):
    try:
        # The page re-renders as data arrives: an element found a moment ago may be gone; look again.
        return WebDriverWait(driver, timeout, poll_frequency=0.1,
                             ignored_exceptions=(StaleElementReferenceException,)).until(lambda d: cond())
    except Exception as e:  # noqa: BLE001 (selenium's TimeoutException, and what the condition raises)
        check("wait for " + what, False, repr(e))
        return None


def click(by, selector, timeout=10):
    """Finds the element and clicks it, again if the page re-rendered it in between (the Lab, run and Runs pages
    redraw as the server reports: an element found a moment ago may be gone, which made the test flaky under load)."""
    end = time.time() + timeout
    while True:
        try:
            driver.find_element(by, selector).click()
            return True
        except (StaleElementReferenceException, NoSuchElementException):
            if time.time() > end:
                check("click " + selector, False, "not found or always re-rendered within %d s" % timeout)
                return False
            time.sleep(0.1)


def text_of(by, selector, timeout=10):
    """The element's text, read again if the page re-rendered it between finding and reading (see click())."""
    end = time.time() + timeout
    while True:
        try:
            return driver.find_element(by, selector).text
        except StaleElementReferenceException:
            if time.time() > end:
                raise
            time.sleep(0.1)


def session_cookie():
    """The browser's vb_session value (Path=/api: WebDriver's own cookie call sees only the page's path)."""
    cookies = driver.execute_cdp_cmd("Network.getAllCookies", {}).get("cookies", [])
    return next((c.get("value") for c in cookies if c.get("name") == "vb_session"), None)


def console_errors(allowed=()):
    """SEVERE console entries since the last call, minus the allowed patterns."""
    out = []
    for e in driver.get_log("browser"):
        if e.get("level") != "SEVERE":
            continue
        if any(re.search(a, e.get("message", "")) for a in allowed):
            continue
        out.append(e.get("message"))
    return out


def no_overflow(page):
    for width in (1400, 1024):
        driver.set_window_size(width, 900)
        time.sleep(0.3)  # dygraphs redraws on resize
        inner, scroll = driver.execute_script(
            "return [window.innerWidth, document.documentElement.scrollWidth];")
        check("%s: no horizontal overflow at %d px" % (page, width), scroll <= inner, "scrollWidth %d > %d" % (scroll, inner))
    driver.set_window_size(1400, 900)


def overflowing(width):
    """Elements of the page wider than the viewport at `width` px (a table that overflows its section)."""
    driver.set_window_size(width, 900)
    time.sleep(0.3)
    return driver.execute_script("""
        // What scrolls inside a container of its own (overflow-x auto) is allowed; the container must fit.
        const w = document.documentElement.clientWidth, out = [];
        const inScroller = (e) => { for (let a = e.parentElement; a && a !== document.body; a = a.parentElement)
          if (getComputedStyle(a).overflowX !== 'visible') return true; return false; };
        for (const e of document.querySelectorAll('body *')) {
          if (e.closest('[hidden]') || e.offsetParent === null || inScroller(e)) continue;
          const r = e.getBoundingClientRect();
          const own = getComputedStyle(e).overflowX === 'visible' ? e.scrollWidth : 0;
          if (r.right > w + 1 || own > w + 1)
            out.push(e.tagName.toLowerCase() + (e.id ? '#' + e.id : '') + (e.className && e.className.baseVal === undefined ? '.' + e.className : '') + ' ' + Math.round(r.right) + '/' + e.scrollWidth);
        }
        return out.slice(0, 8);""")


def shot_at(name, width):
    driver.set_window_size(width, 900)
    time.sleep(0.5)
    driver.save_screenshot(os.path.join(shots, "web-%s-%d.png" % (name, width)))


def download(path, token):
    req = urllib.request.Request(base + path, headers={"Authorization": "Bearer " + token})
    with urllib.request.urlopen(req, timeout=60) as r:
        return r.headers.get("Content-Type", ""), r.read()


def page_rows():
    return driver.execute_script(
        "return Array.from(document.querySelectorAll('#runs tr[data-run]')).map(r => r.dataset.run);")


def page_info():
    e = driver.find_elements(By.ID, "page-info")
    return e[0].text if e else ""


def go(hash_):
    driver.execute_script("location.hash = arguments[0];", hash_)


def shot(name, scroll_to=None):
    driver.set_window_size(1400, 900)
    time.sleep(0.4)
    if scroll_to:
        driver.execute_script("document.querySelector(arguments[0]).scrollIntoView();", scroll_to)
        time.sleep(0.2)
    driver.save_screenshot(os.path.join(shots, "web-%s.png" % name))


# ---- issue 28 (charts, units, compare, sweeps, run charts, diagnosis): helpers and checks of D1's pages.
def page_shots(name, widths=(1400, 1024)):
    """web-NAME-WIDTH.png of the whole page (the window made as tall as the page, at most 5000 px)."""
    for width in widths:
        driver.set_window_size(width, 900)
        time.sleep(0.5)  # dygraphs redraws on resize
        height = driver.execute_script("return document.documentElement.scrollHeight;")
        driver.set_window_size(width, min(max(height + 140, 900), 5000))
        time.sleep(0.4)
        driver.save_screenshot(os.path.join(shots, "web-%s-%d.png" % (name, width)))
    driver.set_window_size(1400, 900)


def chart_info(selector):
    """For each chart (.vb-chart) under `selector`: its plot area in page pixels, its x range, its axis texts."""
    return driver.execute_script("""
      return Array.from(document.querySelectorAll(arguments[0] + ' .vb-plot')).map((d) => {
        const c = d.vbChart; if (!c || !c.g) return null;
        const a = c.g.getArea(), b = d.getBoundingClientRect();
        return {left: b.left + a.x, right: b.left + a.x + a.w, top: b.top + a.y, bottom: b.top + a.y + a.h,
                x: c.g.xAxisRange(), ylabel: (d.querySelector('.dygraph-ylabel') || {}).textContent || '',
                xlabel: (d.querySelector('.dygraph-xlabel') || {}).textContent || '',
                yticks: Array.from(d.querySelectorAll('.dygraph-axis-label-y')).map((e) => e.textContent),
                title: d.closest('.vb-chart').querySelector('.vb-chart-title').textContent,
                legend: Array.from(d.closest('.vb-chart').querySelectorAll('.vb-legend-item')).map((e) =>
                  [e.textContent, e.querySelector('i').style.background, (e.querySelector('a') || {}).href || '']),
                labels: Array.from(d.querySelectorAll('.vb-point-label')).map((e) => {
                  const r = e.getBoundingClientRect(); return [e.textContent, r.left, r.right, r.top, r.bottom]; })};
      });""", selector)


def check_downloads(selector, what):
    """The chart's SVG has its series and texts; its PNG is an image (made in the page, as the buttons do)."""
    out = driver.execute_async_script("""
      const done = arguments[arguments.length - 1];
      const d = document.querySelector(arguments[0] + ' .vb-plot');
      const box = document.querySelector(arguments[0] + '.vb-chart, ' + arguments[0] + ' .vb-chart');
      if (!box) { done(['no chart']); return; }
      const buttons = box.querySelectorAll('.dl-svg, .dl-png').length;
      let svg;
      if (d && d.vbChart) svg = VBCharts.toSvg(d.vbChart); else svg = box.querySelector('svg').cloneNode(true);
      const text = VBCharts.svgText(svg);
      VBCharts.pngOf(svg).then((b) => done([buttons, text.length, (text.match(/<(polyline|rect|circle)/g) || []).length,
        (text.match(/<text/g) || []).length, b.type, b.size])).catch((e) => done(['png: ' + e.message]));
    """, selector)
    ok = len(out) == 6 and out[0] == 2 and out[2] >= 2 and out[3] >= 4 and out[4] == "image/png" and out[5] > 2000
    check("%s: PNG and SVG downloads (SVG with series and texts, PNG an image)" % what, ok, out)


def check_compare_page(batch, runs):
    header = [e.text for e in driver.find_elements(By.CSS_SELECTOR, "#comparison th")]
    metric_heads = [e.text for e in driver.find_elements(By.CSS_SELECTOR, "#comparison th[data-metric]")]
    check("compare: headers carry the CLI's units and SI prefixes (RMSE [mA], driver loss [mW])",
          "RMSE [mA]" in header and any(h.startswith("driver loss [") for h in header), header)
    check("compare: a readable subset by default (at most 9 metrics of more)", 3 <= len(metric_heads) <= 9, metric_heads)
    chooser = driver.find_elements(By.CSS_SELECTOR, ".columns-chooser input[type=checkbox]")
    check("compare: a column chooser with every metric", len(chooser) > len(metric_heads), len(chooser))
    cells = [e.text for e in driver.find_elements(By.CSS_SELECTOR, "#comparison td.num")]
    check("compare: no raw SI value with 5+ decimals in the table", not any(re.match(r"^-?0\.0000", c) for c in cells), cells[:20])
    info = chart_info("#pareto")
    sc = info[0] if info else None
    check("compare: the scatter's effort axis is the comparison's effort metric, labelled with its unit",
          sc is not None and sc["xlabel"].startswith("driver loss [") and sc["ylabel"] == "RMSE [mA]", sc and (sc["xlabel"], sc["ylabel"]))
    inside = sc is not None and len(sc["labels"]) == 4 and all(
        l[1] >= sc["left"] - 1 and l[2] <= sc["right"] + 1 and l[3] >= sc["top"] - 1 and l[4] <= sc["bottom"] + 1 for l in sc["labels"])
    check("compare: every scatter point has its label inside the plot area", inside, sc and (sc["labels"], sc["left"], sc["right"]))
    check("compare: the Pareto front is drawn", sc is not None and any(l[0] == "Pareto front" for l in sc["legend"]), sc and sc["legend"])
    # One colour per case across the table, the scatter and the overlays.
    swatches = driver.execute_script("""return Array.from(document.querySelectorAll('#comparison tr')).slice(1).map((r) =>
        [r.querySelector('td i.swatch').parentNode.textContent.trim(), r.querySelector('td i.swatch').style.background]);""")
    legend = {l[0]: l[1] for l in sc["legend"]} if sc else {}
    check("compare: a case has one colour in the table and the scatter",
          bool(swatches) and all(legend.get(n) == c for n, c in swatches), (swatches, legend))
    over = chart_info("#overlays")
    check("compare: the overlays are drawn with their legends below, linking to the runs",
          len(over) >= 2 and all(any(("#%s" % r["id"]) in l[0] and l[2].endswith("#/run/%s" % r["id"]) for l in over[0]["legend"])
                                 for r in runs), over and over[0]["legend"])
    check("compare: the overlays share one time axis", len(over) >= 2 and all(abs(o["left"] - over[0]["left"]) <= 2 and
                                                                             o["x"] == over[0]["x"] for o in over), over and [(o["left"], o["x"]) for o in over])
    links = [a.get_attribute("href") for a in driver.find_elements(By.CSS_SELECTOR, "#comparison td a[href*='#/run/']")]
    check("compare: rows link to their runs", all(any(h.endswith("#/run/%s" % r["id"]) for h in links) for r in runs), links)
    check("compare: the scatter's legend links to the runs",
          sc is not None and all(any(l[2].endswith("#/run/%s" % r["id"]) for l in sc["legend"]) for r in runs), sc and sc["legend"])
    check_downloads("#pareto", "compare scatter")


def check_diagnosis_page():
    size = text_of(By.CSS_SELECTOR, "#diagnosis-report .verdict-box")
    check("diagnosis: the verdict with its size (the gap before and after, with units)",
          re.search(r"closes \d+ % of the hold-out gap: RMSE [0-9.]+ [mµ]?A → [0-9.]+ [mµ]?A", size), size)
    check("diagnosis: the effect's fitted parameter with its unit (supply_resistance.R_s in ohm)",
          re.search(r"supply_resistance\.R_s = [0-9.]+ [mk]?ohm ± [0-9.]+ [mµ]?ohm", size), size)
    check("diagnosis: button enabled again", driver.find_element(By.CSS_SELECTOR, "button.diagnose").is_enabled())
    over = chart_info("#diagnosis-overlays .diagnosis-overlay")
    check("diagnosis: measured and model overlaid per run, before and after", len(over) >= 2 and all(
        [l[0] for l in o["legend"]][:2] == ["measured", "nominal model (before)"] and len(o["legend"]) == 3 for o in over),
        [o["legend"] for o in over][:2])
    # Under each overlay its residual, measured - model before and after, computed from the overlay's own rows.
    res = driver.execute_script("""
      const ov = Array.from(document.querySelectorAll('#diagnosis-overlays .diagnosis-overlay .vb-plot')).map((d) => d.vbChart);
      const rs = Array.from(document.querySelectorAll('#diagnosis-overlays .diagnosis-residual .vb-plot')).map((d) => d.vbChart);
      let bad = 0, n = 0;
      ov.forEach((c, i) => { const r = rs[i]; if (!r) { bad++; return; }
        c.rows.forEach((row, k) => { for (const j of [1, 2]) { const want = row[j + 1] === null || row[1] === null ? null : row[1] - row[j + 1];
          const got = r.rows[k][j]; n++; if (want === null ? got !== null : Math.abs(got - want) > 1e-12) bad++; } }); });
      return [ov.length, rs.length, n, bad, rs.length ? rs[0].opts.series.map((s) => s.name) : []];""")
    check("diagnosis: a residual chart (measured - model, before and after) under each overlay",
          res[0] >= 2 and res[0] == res[1] and res[2] > 0 and res[3] == 0 and len(res[4]) == 2 and
          res[4][0].startswith("measured − nominal") and res[4][1].endswith("(after)"), res)
    bars = driver.find_elements(By.CSS_SELECTOR, "#diagnosis-phases .vb-bar")
    check("diagnosis: residual by phase as bars", len(bars) >= 4, len(bars))
    check("diagnosis: detection limits shown", bool(driver.find_elements(By.CSS_SELECTOR, "#detection-limits")))
    # Every qualifier the text report gives a limit (the range's end, the range's weakest) is on the page too.
    report = text_of(By.CSS_SELECTOR, "#diagnosis-report pre.report")
    limits = text_of(By.ID, "detection-limits")
    for said in ("the range's weakest", "the range's end"):
        check("diagnosis: a detection limit at %s is said so on the page as in the report" % said,
              (said in report) == (said in limits), (said, report[-800:], limits[-800:]))
    report_w, main_w = driver.execute_script("return [document.querySelector('#diagnosis-report pre.report').clientWidth, "
                                             "document.querySelector('#main').clientWidth];")
    check("diagnosis: the text report is full width", report_w >= 0.9 * (main_w - 40), (report_w, main_w))
    have = driver.find_elements(By.ID, "improved-model")
    check("diagnosis: the improved model can be downloaded (or the page says there is none)",
          bool(have) or bool(driver.find_elements(By.ID, "improved-model-none")))
    if have:
        check("diagnosis: the improved model download is a JSON file", have[0].get_attribute("download") == "improved-model.json")
    else:
        print("note: DiagnoseRunsResponse.improved_model_json empty on this server: no model to download")
    check_downloads("#diagnosis-phases", "diagnosis bars")


def check_sweep_page(batch, n):
    go("#/compare?batch=%s" % batch)
    rows = wait(lambda: (lambda r: r if len(r) == n else None)(driver.find_elements(By.CSS_SELECTOR, "#comparison tr")[1:]),
                what="the sweep's table")
    header = [e.text for e in driver.find_elements(By.CSS_SELECTOR, "#comparison th")]
    sweep_heads = [e.text for e in driver.find_elements(By.CSS_SELECTOR, "#comparison th.sweep")]
    check("sweep: one column per sweep axis (duty, pressure, frequency)", len(sweep_heads) == 3 and
          any(h.startswith("duty") for h in sweep_heads), sweep_heads)
    # The cells in one call (a WebDriver round trip per cell of 147 rows takes seconds).
    table = driver.execute_script("return Array.from(document.querySelectorAll('#comparison tr')).slice(1).map((r) => "
                                  "Array.from(r.querySelectorAll('td')).map((c) => c.textContent.trim()));")
    names = [r[0] for r in table]
    check("sweep: case names without the sweep point", bool(names) and not any("sweep:" in x for x in names), names[:3])
    # Duty 0: the valve stays shut, its mean position is exactly 0 and shows as 0, not as a missing value.
    col = [k for k, h in enumerate(header) if h.startswith("mean x")]
    duty = [k for k, h in enumerate(header) if h.startswith("duty")]
    zero = [cells[col[0]] for cells in table if duty and col and cells[duty[0]] == "0"]
    check("sweep: a metric at exactly 0 shows 0 (duty 0: mean position 0)", bool(zero) and all(z == "0" for z in zero), zero)
    curves = wait(lambda: (lambda c: c if len(c) >= 2 and all(c) else None)(chart_info("#sweep-section")), what="sweep curves")
    curves = curves or []
    check("sweep: position against duty, one curve per pressure (fig8) and per frequency (fig9)",
          len(curves) == 2 and all(c["xlabel"].startswith("duty") and c["ylabel"].startswith("mean x") for c in curves) and
          [len(c["legend"]) for c in curves] == [4, 3], [(c["title"], c["xlabel"], c["ylabel"], len(c["legend"])) for c in curves])
    heat = driver.find_elements(By.CSS_SELECTOR, "#sweep-section svg.vb-heatmap")
    check("sweep: a heat map per 2-D sweep", len(heat) == 2, len(heat))
    check_downloads("#sweep-section .sweep-curve", "sweep curve")


def check_run_charts():
    charts = wait(lambda: (lambda c: c if len(c) >= 3 and all(c) else None)(chart_info("#traces")), what="run charts")
    charts = charts or []
    titles = [c["title"] for c in charts]
    check("run: current, position, voltage and gate charts", len(charts) >= 3 and "Gate (logic level)" in titles, titles)
    lefts = [c["left"] for c in charts]
    rights = [c["right"] for c in charts]
    check("run: the time axes line up within 2 px", bool(lefts) and max(lefts) - min(lefts) <= 2 and max(rights) - min(rights) <= 2,
          (lefts, rights))
    check("run: the charts show one time range", all(c["x"] == charts[0]["x"] for c in charts), [c["x"] for c in charts])
    gate = [c for c in charts if c["title"].startswith("Gate")]
    check("run: the gate chart is a logic level, not volts", bool(gate) and "V" not in gate[0]["ylabel"] and
          gate[0]["yticks"] == ["0 (off)", "1 (on)"], gate and (gate[0]["ylabel"], gate[0]["yticks"]))
    pos = [c for c in charts if c["title"] == "Spool position"]
    check("run: position in a prefixed unit (mm or µm) with distinct ticks", bool(pos) and re.search(r"\[(mm|µm)\]", pos[0]["ylabel"])
          and len(set(pos[0]["yticks"])) == len(pos[0]["yticks"]) >= 3, pos and (pos[0]["ylabel"], pos[0]["yticks"]))
    cur = [c for c in charts if c["title"] == "Coil current"]
    check("run: current in A or mA", bool(cur) and re.search(r"\[m?A\]", cur[0]["ylabel"]), cur and cur[0]["ylabel"])
    # A drag over the position chart zooms every chart to the same window; the ticks stay distinct.
    from selenium.webdriver.common.action_chains import ActionChains
    plot = driver.find_elements(By.CSS_SELECTOR, "#traces .trace-position .vb-plot")
    if plot:
        w = plot[0].size["width"]
        ActionChains(driver).move_to_element_with_offset(plot[0], int(-w * 0.1), 0).click_and_hold() \
            .move_by_offset(int(w * 0.05), 0).release().perform()
        zoomed = wait(lambda: (lambda c: c if c and all(x and x["x"][1] - x["x"][0] < 0.5 * (charts[0]["x"][1] - charts[0]["x"][0])
                                                         for x in c) else None)(chart_info("#traces")), what="zoomed charts")
        zoomed = zoomed or []
        check("run: a zoom on one chart zooms all to one window",
              len(zoomed) == len(charts) and all(abs(z["x"][0] - zoomed[0]["x"][0]) < 1e-9 and abs(z["x"][1] - zoomed[0]["x"][1]) < 1e-9
                                                 for z in zoomed), [z["x"] for z in zoomed])
        zp = [c for c in zoomed if c["title"] == "Spool position"]
        check("run: zoomed position ticks are distinct", bool(zp) and len(set(zp[0]["yticks"])) == len(zp[0]["yticks"]),
              zp and zp[0]["yticks"])
        driver.execute_script("document.querySelector('#traces .trace-position .vb-plot').vbChart.g.resetZoom();")
    check_downloads("#traces .trace-current", "run chart")


try:
    base = None
    for _ in range(400):
        log.seek(0)
        m = re.search(r"web dashboard on (http://\S+)/", log.read())
        if m:
            base = m.group(1)
            break
        time.sleep(0.05)
    check("server serves the dashboard", base is not None, open(os.path.join(work, "server.log")).read())
    if base is None:
        raise SystemExit(1)

    for _ in range(1800):  # the nights' runs first, so that the benches are idle for what follows
        if len(api("GET", "/api/nights", VIEWER).get("nights", [])) >= NIGHTS:
            break
        time.sleep(0.1)
    night = api("GET", "/api/nights", VIEWER).get("nights", [{}])[0]
    check("the night ran and regressed", night.get("verdict") == "regressed", night)

    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for a in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--window-size=1400,900",
              "--proxy-server=http://127.0.0.1:9", "--no-first-run", "--disable-extensions",
              "--user-data-dir=" + os.path.join(work, "chromium-profile")):
        opts.add_argument(a)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    # A time zone other than the server's UTC, so that local times are seen to be local.
    driver = webdriver.Chrome(service=Service(DRIVER, env=dict(os.environ, TZ="Europe/Berlin")), options=opts)
    driver.set_page_load_timeout(20)

    # 1. Log in with the operator's token.
    driver.get(base + "/")
    driver.find_element(By.ID, "token").send_keys(OPERATOR)
    driver.find_element(By.ID, "login-button").click()
    # Texts read inside the wait: the Lab page re-renders its tables as the benches report.
    rows = wait(lambda: [r.text for r in driver.find_elements(By.CSS_SELECTOR, "#benches tr")[1:]] or None,
                what="bench table")
    check("the lab lists both benches", rows is not None and len(rows) == 2 and "idle" in rows[0], rows)
    check("the token stays in sessionStorage",
          driver.execute_script("return sessionStorage.getItem('valvebench.token')") == OPERATOR)

    # 2. Submit a long real-time run from the Submit page.
    with open(os.path.join(examples_dir, "standard", "e3.json")) as f:
        spec = json.load(f)
    # Pull in, then hold with a 20 kHz PWM at duty 0.3: the live view must show the hold as its duty (issue 37).
    spec.update({"name": "web-live", "realtime": True, "duration_s": 30.0,
                 "controller": {"open_loop_pwm": {"segments": [{"start_s": 0.0, "frequency_Hz": 0.0, "duty": 1.0},
                                                               {"start_s": 0.05, "frequency_Hz": 20000.0, "duty": 0.3}]}}})
    go("#/submit")
    area = wait(lambda: driver.find_elements(By.ID, "spec") or None, what="spec editor")
    driver.execute_script("document.getElementById('spec').value = arguments[0];", json.dumps(spec, indent=2))
    driver.find_element(By.ID, "submit").click()
    link = wait(lambda: driver.find_elements(By.CSS_SELECTOR, "#submit-result a[href^='#/run/']") or None,
                what="submission result")
    live_id = link[0].text.lstrip("#") if link else None
    check("the submission is queued", live_id is not None and live_id.isdigit(),
          text_of(By.ID, "main")[-600:])
    said = text_of(By.ID, "submit-result")
    check("the submission says how many runs and links the batch's comparison",
          re.search(r"Queued batch \d+: 1 run \(#\d+\)", said) and
          bool(driver.find_elements(By.CSS_SELECTOR, "#submit-result a#compare-submitted[href^='#/compare?batch=']")), said)
    if live_id is None:
        raise RuntimeError("no run to follow")

    # 3. The lab shows it running, with live samples that keep arriving (SSE).
    go("#/")

    def samples():
        c = driver.find_elements(By.CSS_SELECTOR, ".live-run[data-run='%s'] .live-count" % live_id)
        return int(c[0].get_attribute("data-samples") or 0) if c else 0
    first = wait(lambda: samples() > 0 and samples(), what="first live samples")
    time.sleep(1.0)
    later = samples()
    check("live samples arrive and keep arriving", bool(first) and later > first, (first, later))
    bench_text = text_of(By.CSS_SELECTOR, "#benches")
    check("the bench shows what it runs", ("running #%s" % live_id) in bench_text, bench_text)
    queue_text = text_of(By.CSS_SELECTOR, "#queue")
    check("the queue shows the run with an ETA", "web-live" in queue_text and re.search(r"\d+(\.\d)? s|min", queue_text),
          queue_text)
    shot("lab")
    no_overflow("lab")

    # 4. Open it and cancel it.
    go("#/run/" + live_id)
    btn = wait(lambda: driver.find_elements(By.ID, "cancel") or None, what="cancel button")
    wait(lambda: int(driver.find_element(By.CSS_SELECTOR, "#traces .live-count").get_attribute("data-samples") or 0) > 0,
         what="live samples on the run page")
    # The gate is drawn as its duty over each streamed interval: the 20 kHz hold at 0.3 streamed at 200 Hz reads
    # 0.3, not a level of 0 or 1 at the kept instants.
    duty = wait(lambda: driver.execute_script("""
        const d = document.querySelector('#traces .live-gate .vb-plot');
        const g = d && d.vbChart && d.vbChart.g; if (!g) return null;
        const v = []; for (let r = 0; r < g.numRows(); r++) { const y = g.getValue(r, 1); if (y !== null) v.push(y); }
        return v.some((y) => y > 0.25 && y < 0.35) ? [d.closest('.vb-chart').querySelector('.vb-chart-title').textContent, v]
                                                   : null;"""), what="the live duty of the PWM hold")
    check("the live gate is drawn as its duty over each interval (0.3 for a 20 kHz hold at 0.3)",
          duty is not None and "duty" in duty[0] and all(-1e-9 <= y <= 1 + 1e-9 for y in duty[1]) and
          sum(1 for y in duty[1] if abs(y - 0.3) < 0.01) >= len(duty[1]) // 2,
          duty and (duty[0], duty[1][:40]))
    check("the server says it dropped nothing for an idle page",
          driver.find_element(By.CSS_SELECTOR, "#traces .live-count").get_attribute("data-dropped") == "0")
    # Under load (two processes burning both cores for 5 s while the run streams), the live chart still draws
    # no segment longer than the hole rule allows (5x the 5 ms interval of a 200 Hz stream): a longer interval
    # between two drawn samples is broken by a row of nulls, never bridged (issue 37, point 3).
    burn = "import time\nt = time.time()\nwhile time.time() - t < 5.0:\n    pass\n"
    burners = [subprocess.Popen([sys.executable, "-c", burn]) for _ in range(2)]
    for b in burners:
        b.wait()
    time.sleep(0.6)  # two chart updates
    seg = driver.execute_script("""
        const d = document.querySelector('#traces .live-current .vb-plot');
        const g = d && d.vbChart && d.vbChart.g; if (!g) return null;
        let longest = 0, breaks = 0, rows = g.numRows();
        for (let r = 1; r < rows; r++) {
          const a = g.getValue(r - 1, 1), b = g.getValue(r, 1);
          if (b === null) breaks++;
          if (a !== null && b !== null) longest = Math.max(longest, g.getValue(r, 0) - g.getValue(r - 1, 0));
        }
        return [rows, longest, breaks];""")
    check("under load the live chart bridges no hole (no drawn segment over 25 ms)",
          seg is not None and seg[0] > 100 and seg[1] <= 0.025 + 1e-9, (seg, text_of(By.CSS_SELECTOR, "#traces .live-count")))
    shot("run-live")
    shot("run-live-traces", "#traces")  # the live charts themselves: current, position, the gate's duty
    wait(lambda: driver.find_elements(By.CSS_SELECTOR, "#traces .progress") or None, what="the live progress")
    progress = driver.execute_script("return Array.from(document.querySelectorAll('#main *')).filter((e) => "
                                     "e.children.length === 0 && /^\\d+ %$/.test(e.textContent.trim())).length;")
    check("the run page shows one progress figure", progress == 1, progress)
    if btn:
        click(By.ID, "cancel")
        # Cancel asks for confirmation and a reason (a prompt); the reason is recorded with the user's name.
        alert = wait(lambda: driver.switch_to.alert, what="the cancel confirmation")
        if alert:
            alert.send_keys("valve chatter seen")
            alert.accept()
    cancelled = wait(lambda: "CANCELLED" in driver.find_element(By.TAG_NAME, "h1").text, what="cancelled run")
    check("the run is cancelled from the page", bool(cancelled), text_of(By.TAG_NAME, "h1"))
    stored = api("GET", "/api/runs/" + live_id, VIEWER)["run"]
    check("the store says cancelled, by whom and why", stored["status"] == "CANCELLED" and
          stored.get("reason", "").startswith("cancelled by olga: valve chatter seen"), stored.get("reason"))
    flash_text = text_of(By.ID, "flash")
    check("the page says the result of the cancel", "cancelled" in flash_text.lower(), flash_text)
    # The cancelled run was paced (realtime): what its loop measured is stored with it once its result lands,
    # and its page shows how the loop kept time (ticks, overruns, jitter), as benchctl show does.
    ran = wait(lambda: api("GET", "/api/runs/" + live_id, VIEWER)["run"].get("execution", {}).get("loop"),
               what="the cancelled paced run's stored loop statistics")
    go("#/run/" + live_id)
    # Read inside the wait: the page re-renders as its traces arrive, and an element found a moment ago goes stale.
    kv = wait(lambda: (lambda t: t if "loop" in t else None)(driver.find_element(By.CSS_SELECTOR, ".kv").text),
              what="the run's loop row") or ""
    check("a paced run's page shows how its loop kept time (Run.execution.loop)",
          ran and re.search(r"loop\s+\d+ paced ticks, \d+ overruns, jitter p50 [0-9.]+ [mµ]?s, p99 [0-9.]+ [mµ]?s, "
                            r"max [0-9.]+ [mµ]?s", kv), (ran, kv[-300:]))

    # 4b. A run watched from its start (issue 24, M3): its first sample is at t_s = 0, which proto3 JSON would
    # leave out; the charts must draw it and every later one, without a console error.
    # The run waits behind another on the same bench while the page opens its stream, so the page sees it start.
    console_errors()  # what came before is checked elsewhere
    on_emu1 = dict(spec.get("bench", {}), name="emu-1")
    blocker = api("POST", "/api/runs", OPERATOR, {"spec": dict(spec, name="web-blocker", duration_s=30.0,
                                                                bench=on_emu1)})["run_ids"][0]
    start_id = api("POST", "/api/runs", OPERATOR, {"spec": dict(spec, name="web-from-start", duration_s=3.0,
                                                                 bench=on_emu1)})["run_ids"][0]
    go("#/run/" + start_id)
    wait(lambda: driver.find_elements(By.CSS_SELECTOR, "#traces .live-count") or None, what="the queued run's live view")
    time.sleep(1.0)
    check("the run waits in the queue", api("GET", "/api/runs/" + start_id, VIEWER)["run"]["status"] == "QUEUED")
    api("POST", "/api/runs/%s/cancel" % blocker, OPERATOR, {})
    got = wait(lambda: int(driver.find_element(By.CSS_SELECTOR, "#traces .live-count").get_attribute("data-samples")
                           or 0) > 50, what="live samples of a run watched from its start")
    time.sleep(0.6)  # two chart updates (every 250 ms)
    errs = console_errors()
    check("a run watched from its start charts live without a console error", bool(got) and not errs, errs)
    for _ in range(100):
        if api("GET", "/api/runs/" + start_id, VIEWER)["run"]["status"] not in ("QUEUED", "RUNNING"):
            break
        time.sleep(0.1)

    # 5. A comparison: seed 001's four current laws, then the compare page of that batch.
    with open(os.path.join(examples_dir, "compare-current-controllers.json")) as f:
        sub = api("POST", "/api/runs", OPERATOR, {"spec": json.load(f)})
    batch = sub["batch_id"]
    for _ in range(600):
        runs = api("GET", "/api/runs?batch_id=%s" % batch, VIEWER).get("runs", [])
        if runs and all(r["status"] not in ("QUEUED", "RUNNING") for r in runs):
            break
        time.sleep(0.1)
    check("the comparison's runs finish", all(r["status"] == "DONE" for r in runs), [r["status"] for r in runs])
    go("#/compare?batch=%s" % batch)
    # The rows' texts are read inside the wait, which looks again when the page re-rendered the table.
    table = wait(lambda: [r.text for r in driver.find_elements(By.CSS_SELECTOR, "#comparison tr")[1:]] or None,
                 what="comparison table")
    check("the comparison has one row per law", table is not None and len(table) == 4, table)
    plots = wait(lambda: len(driver.find_elements(By.CSS_SELECTOR, "#pareto canvas, #overlay-current canvas, "
                                                  "#overlay-error canvas")) >= 3 or None, what="comparison plots")
    legend = text_of(By.ID, "overlay-current")
    check("the overlays show every run", all(("#%s" % r["id"]) in legend for r in runs) and plots is not None, legend)
    check_compare_page(batch, runs)
    law_colours = {l[0]: l[1] for l in (chart_info("#pareto") or [{"legend": []}])[0]["legend"]}
    shot("compare")
    page_shots("compare")
    no_overflow("compare")

    # 6. A finished run's page: metrics with units, traces, export links; zoom refetches at full resolution.
    done_id = str(runs[0]["id"])
    go("#/run/" + done_id)
    wait(lambda: len(driver.find_elements(By.CSS_SELECTOR, ".trace-chart canvas")) >= 2 or None, what="trace charts")
    metrics = text_of(By.ID, "metrics")
    check("the run page shows metrics with units and SI prefixes", re.search(r"rmse -?[0-9.]+ [mµn]?A\b", metrics), metrics[:300])
    kv = driver.find_element(By.CSS_SELECTOR, ".kv").text
    check("the run page shows what executing the run measured (Run.execution, stored with the run)",
          re.search(r"execution\s+[0-9.]+ [mµ]?s simulated, \d+ samples, [0-9.]+ [mµ]?s wall", kv), kv[-300:])
    check("the run page names the build that executed the run (Run.execution.build)",
          re.search(r"build\s+valvebench \S+ sha256:[0-9a-f]{32}", kv), kv[-300:])
    # Issue 37: the one unit rule (common/units.h): the page writes a value as benchctl show and Python do.
    fmt = driver.execute_script("return [[81.13e-6, 'm^2'], [0.02773, 'kg'], [7.514e-4, 'kg/s'], [9.533e-4, 'A'],"
                                " [8.67476e-05, 'W'], [2e-3, 'N s/m'], [0, 'kg']].map((c) => VBFormat.value(c[0], c[1]))")
    check("the page writes compound units as benchctl does (mm^2, g, mg/s)",
          fmt == ["81.13 mm^2", "27.73 g", "751.4 mg/s", "953.3 \u00b5A", "86.75 \u00b5W", "2 mN s/m", "0 kg"], fmt)
    # Issue 37, point 3: a live chart never bridges a hole in the stream, and a flat hold is not autoscaled onto
    # rounding. The page's own functions (charts.js), fed a 200 Hz stream with 0.4 s missing.
    live = driver.execute_script("""
        const h = VBCharts.holes(), breaks = [];
        const ts = [];
        for (let i = 0; i < 20; i++) ts.push(i * 0.005);
        for (let i = 0; i < 5; i++) ts.push(0.5 + i * 0.005);
        for (const t of ts) { const b = h.step(t); if (b !== null) breaks.push(b); }
        return [breaks, h.gaps, h.missing_s, VBCharts.minSpanRange([[0, 0.5], [1, 0.5 + 1e-12]], 1e-3),
                VBCharts.minSpanRange([[0, 0.1], [1, 0.4]], 1e-3)];""")
    check("a hole in a live stream is broken, counted and measured, not bridged",
          len(live[0]) == 1 and abs(live[0][0] - 0.1) < 1e-9 and live[1] == 1 and abs(live[2] - 0.4) < 1e-9, live)
    check("a flat 500 mA hold is drawn over at least 2 % of its value, not its rounding",
          live[3] and abs((live[3][1] - live[3][0]) - 0.01) < 1e-9 and live[4] is None, live)
    check("the run page links the export", driver.find_element(By.ID, "export-csv").get_attribute("href")
          .endswith("/api/runs/%s/trace.csv" % done_id))
    check_run_charts()
    shot("run")
    shot("run-traces", "#traces")
    page_shots("run")
    no_overflow("run")

    # 7. The nightly history: the regressed night with its verdict and links to its runs and comparison.
    go("#/nights")
    row = wait(lambda: driver.find_elements(By.CSS_SELECTOR, "#nights tr")[1:] or None, what="nights table")
    text = row[0].text if row else ""
    check("the nights page shows the regressed night", "regressed" in text and night.get("date", "?") in text, text)
    links = [a.get_attribute("href") for a in row[0].find_elements(By.TAG_NAME, "a")] if row else []
    check("the night links to its runs, its failed runs and its comparison",
          any(h.endswith("#/runs?batch=%s" % night.get("batch_id")) for h in links) and
          any(h.endswith("#/compare?batch=%s" % night.get("batch_id")) for h in links), links)
    cases = night.get("regressed_cases", [])
    check("the night names its regressed case", cases == ["current-hold/pi"] or (len(cases) == 1 and "pi" in cases[0]), cases)
    # The bench twin's column: the PI gain cut on an unchanged valve is the code's doing (docs/track.md).
    cause = row[0].find_elements(By.CSS_SELECTOR, "td.valve-cause") if row else []
    check("the night names the code as its cause", bool(cause) and "cause: code" in cause[0].text and
          night.get("cause") == "code", (cause[0].text if cause else "", night.get("cause"), night.get("cause_reason")))

    case_links = row[0].find_elements(By.CSS_SELECTOR, "td.regressed-cases a") if row else []
    shot("nights")
    if case_links:
        click(By.CSS_SELECTOR, "td.regressed-cases a")
        runs_rows = wait(lambda: driver.find_elements(By.CSS_SELECTOR, "#runs tr")[1:] or None, what="regressed runs")
        names = [r.find_elements(By.TAG_NAME, "td")[3].text for r in runs_rows or []]
        check("the regressed case links to its runs in the night's batch", len(names) >= 1 and
              all(n.startswith(cases[0]) for n in names), names)
    else:
        check("the night links its regressed case", False, row[0].text if row else "")

    # 7a. Bench health: emu-1's tracked parameters night by night with the reference's limits, its fits, no flag.
    go("#/health")
    wait(lambda: len(driver.find_elements(By.CSS_SELECTOR, "#health-emu-1 .health-parameter canvas")) >= 2 or None,
         what="bench health charts")
    health = api("GET", "/api/health?bench=emu-1", VIEWER)
    bench_h = (health.get("benches") or [{}])[0]
    check("GetBenchHealth through the web: emu-1 with its nights", bench_h.get("bench") == "emu-1" and
          len(bench_h.get("nights", [])) == NIGHTS, bench_h.get("nights"))
    names = [p["name"] for p in bench_h.get("parameters", [])]
    shown = driver.execute_script(
        "return Array.from(document.querySelectorAll('#health-emu-1 .health-parameter')).map((b) => {"
        "  const c = b.querySelector('.vb-plot').vbChart;"
        "  return [b.dataset.parameter, c.rows.length, c.rows.filter((r) => r[1] !== null).length,"
        "          c.rows.every((r) => r[3] < r[2] && r[2] < r[4])]; });")
    check("a chart per tracked parameter, R first", [x[0] for x in shown] == names and names[:1] == ["R"], (shown, names))
    check("each chart: a value per night and the limits around the reference's mean",
          bool(shown) and all(x[1] == NIGHTS and x[2] == NIGHTS and x[3] for x in shown), shown)
    info = chart_info("#health-emu-1")
    r_chart = [c for c in info if c and c["title"].startswith("R ")]
    check("R's chart in ohm with its limits in the legend", bool(r_chart) and "[ohm]" in r_chart[0]["ylabel"] and
          any("upper limit" in x[0] for x in r_chart[0]["legend"]), r_chart[:1])
    check("the fit of each night beside its noise floor", any(c and c["title"].startswith("Fit of each night") and
                                                             "[mA]" in c["ylabel"] for c in info), [c and c["title"] for c in info])
    check("an unchanged valve: no parameter flagged", text_of(By.CSS_SELECTOR, "#health-emu-1 .health-clean") ==
          "No parameter flagged over %d nights." % NIGHTS and not bench_h.get("flags"), bench_h.get("flags"))
    try:
        bad = api("GET", "/api/health?bench=no-such-bench", VIEWER)
    except urllib.error.HTTPError as e:
        bad = (e.code, e.read().decode())
    check("an unknown bench is a 404 naming it", bad[0] == 404 and "no-such-bench" in bad[1], bad)
    page_shots("health")

    # 7b. The diagnosis: practice set p07 imported with benchctl, diagnosed on the server from the page.
    p07 = os.path.abspath(os.path.join(examples_dir, "..", "..", "shared", "gapbench", "practice", "p07"))
    benchctl = os.path.join(os.path.dirname(server_bin), "benchctl")
    grpc_addr = re.search(r"listening on (\S+) ", open(os.path.join(work, "server.log")).read())
    if os.path.isdir(p07) and os.path.exists(benchctl) and grpc_addr:
        imported = subprocess.run([benchctl, "import", p07, "--json", "--server", grpc_addr.group(1),
                                   "--token", OPERATOR], capture_output=True, text=True, timeout=120)
        check("benchctl imports p07", imported.returncode == 0, imported.stdout + imported.stderr)
        go("#/diagnosis")
        button = wait(lambda: driver.find_elements(By.CSS_SELECTOR, "button.diagnose") or None, what="diagnose button")
        if button:
            click(By.CSS_SELECTOR, "button.diagnose")
            busy = driver.execute_script("return [document.querySelector('button.diagnose').disabled, "
                                         "!!document.querySelector('#diagnosis-report .progress-bar')];")
            check("diagnosis: the button is disabled and a progress shows while it runs", busy == [True, True], busy)
        verdict = wait(lambda: driver.find_elements(By.CSS_SELECTOR, "#diagnosis-report .verdict") or None,
                       timeout=120, what="diagnosis verdict")
        text = verdict[0].text if verdict else ""
        check("the page diagnoses the imported runs on the server", text == "supply_resistance", text)
        check_diagnosis_page()
        shot("diagnosis")
        page_shots("diagnosis")
        no_overflow("#/diagnosis with its report")
        # The overlay link opens the imported runs' traces overlaid.
        click(By.CSS_SELECTOR, "a.overlay")
        over = wait(lambda: driver.find_elements(By.CSS_SELECTOR, "#overlay-current canvas") or None, what="diagnosis overlay")
        check("diagnosis: the overlay link opens a populated overlay", bool(over) and
              len(driver.find_elements(By.CSS_SELECTOR, "#overlay-current .vb-legend-item")) >= 2,
              text_of(By.ID, "main")[:300])
        page_shots("diagnosis-overlay", widths=(1400,))
        # Re-run of an imported run: refused with a clear message by the API, the page's button disabled.
        imp = api("GET", "/api/runs?tag=imported&page_size=1", VIEWER)["runs"][0]["id"]
        try:
            api("POST", "/api/runs/%s/rerun" % imp, OPERATOR, {})
            refused = None
        except urllib.error.HTTPError as e:
            refused = (e.code, json.loads(e.read()))
        check("an imported run's re-run is refused as a precondition, saying why",
              refused is not None and refused[0] == 409 and "imported measurement" in refused[1]["message"], refused)
        go("#/run/%s" % imp)
        rr = wait(lambda: driver.find_elements(By.ID, "rerun") or None, what="re-run button")
        check("an imported run's Re-run button is disabled with a tooltip", bool(rr) and not rr[0].is_enabled() and
              "imported" in (rr[0].get_attribute("title") or ""), rr and rr[0].get_attribute("title"))
    else:
        print("note: no ../shared/gapbench/practice/p07 or benchctl beside the server: the diagnosis step is skipped")

    # 7c. An empty Compare page offers the recent batches.
    go("#/compare")
    recent = wait(lambda: driver.find_elements(By.CSS_SELECTOR, "#recent-batches a.compare-batch") or None, what="recent batches")
    check("an empty Compare page offers the recent batches",
          bool(recent) and any(a.get_attribute("href").endswith("#/compare?batch=%s" % batch) for a in recent or []))

    # 7d. Seed 000's static map (examples/static-map.json, Figs. 8-9; 147 short emulated runs): one column per
    # sweep axis, position against duty per pressure (fig8) and per PWM frequency (fig9), a heat map each.
    with open(os.path.join(examples_dir, "static-map.json")) as f:
        smap = json.load(f)
    t_sweep = time.time()
    sweep_batch = api("POST", "/api/runs", OPERATOR, {"spec": smap})["batch_id"]
    for _ in range(1200):
        sruns = api("GET", "/api/runs?page_size=200&batch_id=%s" % sweep_batch, VIEWER).get("runs", [])
        if sruns and all(r["status"] not in ("QUEUED", "RUNNING") for r in sruns):
            break
        time.sleep(0.1)
    print("note: the static map's %d runs took %.1f s" % (len(sruns), time.time() - t_sweep))
    check_sweep_page(sweep_batch, len(sruns))
    page_shots("sweep")
    no_overflow("compare (sweep)")

    # 7e. A 1-D sweep of four laws (seed 001's comparison at three supply voltages): one curve per law, each in
    # its law's colour, the same as in the scatter of the comparison above.
    with open(os.path.join(examples_dir, "compare-current-controllers.json")) as f:
        laws = json.load(f)
    laws["sweep"] = [{"field": "conditions.supply_V", "values": [20, 24, 28]}]
    law_batch = api("POST", "/api/runs", OPERATOR, {"spec": laws})["batch_id"]
    for _ in range(600):
        lruns = api("GET", "/api/runs?page_size=200&batch_id=%s" % law_batch, VIEWER).get("runs", [])
        if lruns and all(r["status"] not in ("QUEUED", "RUNNING") for r in lruns):
            break
        time.sleep(0.1)
    go("#/compare?batch=%s" % law_batch)
    curves = wait(lambda: (lambda c: c if len(c) == 1 and all(c) else None)(chart_info("#sweep-section")), what="1-D sweep curve")
    c1 = curves[0] if curves else None
    check("1-D sweep: one chart, one curve per law against the swept supply voltage",
          c1 is not None and sorted(l[0] for l in c1["legend"]) == ["fuzzy", "hysteresis", "pi", "predictive"] and
          c1["xlabel"] == "supply [V]",
          c1 and (c1["xlabel"], c1["legend"]))
    check("1-D sweep: a law keeps its colour from the comparison's scatter",
          c1 is not None and all(law_colours.get(l[0]) == l[1] for l in c1["legend"]), (c1 and c1["legend"], law_colours))
    page_shots("sweep-laws", widths=(1400,))

    for page in ("#/runs", "#/nights", "#/diagnosis", "#/submit"):
        go(page)
        time.sleep(0.6)
        check(page + " renders without an error", not driver.find_elements(By.CSS_SELECTOR, "main .error"),
              text_of(By.ID, "main")[:300])
        no_overflow(page)
    go("#/runs")
    time.sleep(0.5)
    shot("runs")
    errors = console_errors()
    check("no console error while operating", not errors, errors)

    # 7b'. Import from the page: a file missing from the dataset is refused naming the file; then p07 whole.
    if os.path.isdir(p07):
        go("#/submit")
        wait(lambda: driver.find_elements(By.ID, "import-files") or None, what="import form")
        driver.find_element(By.ID, "import-name").send_keys("p07-web")
        csvs = sorted(f for f in os.listdir(p07) if f.endswith(".csv"))
        driver.find_element(By.ID, "import-files").send_keys("\n".join(
            [os.path.join(p07, "manifest.json")] + [os.path.join(p07, f) for f in csvs[1:]]))
        driver.find_element(By.ID, "import-button").click()
        err = wait(lambda: driver.find_elements(By.CSS_SELECTOR, "#import-result .error") or None, what="import error")
        text = err[0].text if err else ""
        check("an incomplete dataset is refused naming the missing file", "INVALID_ARGUMENT" in text and csvs[0] in text, text)
        driver.find_element(By.ID, "import-files").clear()
        driver.find_element(By.ID, "import-files").send_keys("\n".join(
            [os.path.join(p07, "manifest.json")] + [os.path.join(p07, f) for f in csvs]))
        driver.find_element(By.ID, "import-button").click()
        ok = wait(lambda: driver.find_elements(By.CSS_SELECTOR, "#import-result .ok a") or None, timeout=60, what="import result")
        imported_batch = ok[0].text if ok else ""
        got = api("GET", "/api/runs?page_size=1000&batch_id=%s" % imported_batch, VIEWER).get("runs", []) if ok else []
        check("the page imports a dataset (its runs stored, tagged imported)", len(got) == len(csvs) and
              all("imported" in r.get("tags", []) for r in got), (imported_batch, len(got), len(csvs)))
        console_errors(allowed=(r"/api/import - Failed to load resource: the server responded with a status of 400",))

    # 7c. The Runs page (issue 28): newest first, paged by the service with its total, sorted by a click on a
    # column header, filtered by submitter; local times with UTC on hover; a duration column.
    listing = api("GET", "/api/runs?page_size=1000", VIEWER)
    all_ids = sorted(int(r["id"]) for r in listing.get("runs", []))
    check("the API says how many runs match (total_size)", int(listing.get("total_size", -1)) == len(all_ids),
          (listing.get("total_size"), len(all_ids)))
    go("#/runs?size=25")
    wait(lambda: page_rows() or None, what="runs table")
    first_page = page_rows()
    check("runs are listed newest first", first_page[:25] == [str(i) for i in sorted(all_ids, reverse=True)[:25]],
          first_page[:5])
    check("the page says which runs it shows of how many",
          page_info() == "showing 1–25 of %d" % len(all_ids), page_info())
    click(By.ID, "page-next")
    wait(lambda: page_rows() and page_rows() != first_page or None, what="the next page")
    check("Next shows the following runs", page_rows()[:1] == [str(sorted(all_ids, reverse=True)[25])] and
          page_info().startswith("showing 26–"), (page_rows()[:2], page_info()))
    click(By.ID, "page-prev")
    wait(lambda: page_rows() == first_page or None, what="the previous page")
    click(By.CSS_SELECTOR, "th[data-order='id'] a")  # newest first -> by id, descending
    time.sleep(0.5)
    click(By.CSS_SELECTOR, "th[data-order='id'] a")  # again: ascending
    asc = wait(lambda: page_rows() and page_rows()[0] == str(all_ids[0]) and page_rows(), what="sorted by id")
    check("a click on a header sorts by it", bool(asc) and [int(i) for i in asc] == all_ids[:len(asc)],
          (asc or [])[:5])
    go("#/runs?submitter=olga&size=25")
    wait(lambda: page_rows() is not None and "submitter=olga" in driver.current_url or None, what="filtered runs")
    time.sleep(0.5)
    subs = driver.execute_script("return Array.from(document.querySelectorAll('#runs tr[data-run] td:nth-child(8)')).map(t => t.textContent);")
    check("the submitter filter keeps olga's runs", subs and all(x == "olga" for x in subs), subs[:5])
    times = driver.find_elements(By.CSS_SELECTOR, "#runs time")
    check("times are local (Europe/Berlin here) with the zone, UTC on hover", times and
          times[0].get_attribute("title").endswith(" UTC") and
          re.match(r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d (CET|CEST|GMT\+[12])$", times[0].text) and
          times[0].text[:19] != times[0].get_attribute("title")[:19],
          (times[0].text, times[0].get_attribute("title")) if times else None)
    durations = driver.execute_script("return Array.from(document.querySelectorAll('#runs tr[data-run] td:nth-child(10)')).map(t => t.textContent);")
    check("the runs show their duration", any(re.search(r"\d s$|min", d) for d in durations), durations[:5])
    go("#/runs?controller=pi_current&size=25")
    wait(lambda: page_rows() and "controller=pi_current" in driver.current_url or None, what="PI runs")
    time.sleep(0.5)
    efforts = driver.execute_script("return Array.from(document.querySelectorAll('#runs tr[data-run] td:nth-child(12) span')).map(t => [t.title, t.textContent]);")
    check("the effort column is the law's comparison effort with its unit (driver loss for a current law)",
          efforts and all(t.startswith("driver_loss_W") and re.search(r"\d [mµk]?W \(driver loss\)$", x)
                          for t, x in efforts), efforts[:5])
    go("#/runs")
    wait(lambda: page_rows() or None, what="runs table")
    for w in (1400, 1024):
        shot_at("runs", w)
    header_text = text_of(By.ID, "session-text")
    check("the header shows the user and the role", "olga" in header_text and "operator" in header_text, header_text)

    # 7d. Downloads of every format the CLI writes, with their content types, parsed as a user would.
    ctype, body = download("/api/runs/%s/trace.h5" % done_id, OPERATOR)
    check("trace.h5 is HDF5", ctype == "application/x-hdf5" and body[:8] == b"\x89HDF\r\n\x1a\n", (ctype, body[:8]))
    ctype_m, body_m = download("/api/runs/%s/trace.mat" % done_id, OPERATOR)
    check("trace.mat is a MAT-file", ctype_m == "application/x-matlab-data" and body_m[:19] == b"MATLAB 5.0 MAT-file",
          (ctype_m, body_m[:20]))
    ctype_c, body_c = download("/api/runs/%s/trace.csv" % done_id, OPERATOR)
    ctype_cc, body_cc = download("/api/compare.csv?batch_id=%s" % batch, OPERATOR)
    ctype_cj, body_cj = download("/api/compare.json?batch_id=%s" % batch, OPERATOR)
    check("comparison downloads have their types", ctype_cc.startswith("text/csv") and
          ctype_cj.startswith("application/json"), (ctype_cc, ctype_cj))
    try:
        import io
        import h5py
        import pandas
        import scipy.io
        with h5py.File(io.BytesIO(body), "r") as h:
            n = h["channels/i_A"].shape[0]
            check("the HDF5 file holds the trace with units", n > 100 and h["channels/i_A"].attrs["units"] in
                  (b"A", "A") and int(h.attrs["run_id"]) == int(done_id), (n, dict(h.attrs)))
        mat = scipy.io.loadmat(io.BytesIO(body_m), squeeze_me=True, struct_as_record=False)["vbrun"]
        check("the MAT file loads with scipy (same samples as the HDF5)", len(mat.channels.i_A) == n,
              len(mat.channels.i_A))
        csv_trace = pandas.read_csv(io.BytesIO(body_c))
        check("trace.csv parses with pandas (same samples)", len(csv_trace) == n and "i_A" in csv_trace.columns,
              (len(csv_trace), list(csv_trace.columns)))
        cmp_csv = pandas.read_csv(io.BytesIO(body_cc))
        check("compare.csv parses with pandas: one row per law", len(cmp_csv) == 4 and "rmse_A" in cmp_csv.columns,
              cmp_csv.columns.tolist())
        check("compare.json parses: one row per law", len(json.loads(body_cj)["rows"]) == 4, body_cj[:200])
        ctype_r, body_r = download("/api/batches/%s/report.html" % batch, OPERATOR)
        check("the batch's HTML report is the CLI's page", ctype_r.startswith("text/html") and
              b"<!doctype html>" in body_r[:200].lower() and b"compare-current-controllers" in body_r and
              all(("run %s:" % r["id"]).encode() in body_r for r in runs), (ctype_r, body_r[:200]))
    except ImportError as e:
        check("python3-h5py, python3-scipy and python3-pandas (scripts/setup.sh) are installed", False, e)
    links = [a.get_attribute("href") or "" for a in driver.find_elements(By.CSS_SELECTOR, "a")]

    # 7e. Every page fits 1024 px: no element wider than the viewport (tables wrap); screenshots at both widths.
    for page, name in (("#/", "lab"), ("#/runs", None), ("#/nights", "nights"), ("#/health", None), ("#/submit", None),
                       ("#/run/" + done_id, None), ("#/compare?batch=%s" % batch, None), ("#/diagnosis", None)):
        go(page)
        time.sleep(1.2)
        for w in (1400, 1024):
            wide = overflowing(w)
            check("%s: no element wider than the viewport at %d px" % (page, w), not wide, wide)
        if name:
            shot_at(name, 1400)
            shot_at(name, 1024)
    go("#/nights")
    nxt = wait(lambda: driver.find_element(By.ID, "next-night").text or None, what="next night")
    check("the Nights page shows the next night's time", nxt and nxt.startswith("Next night: ") and
          re.search(r"\d\d:\d\d:\d\d", nxt), nxt)
    driver.set_window_size(1400, 900)

    # 7f. Dark theme (prefers-color-scheme: dark emulated through CDP): dark background, light text, charts drawn.
    driver.execute_cdp_cmd("Emulation.setEmulatedMedia", {"features": [{"name": "prefers-color-scheme", "value": "dark"}]})
    go("#/run/" + done_id)
    wait(lambda: len(driver.find_elements(By.CSS_SELECTOR, ".trace-chart canvas")) >= 2 or None, what="dark charts")
    bg, fg = driver.execute_script("const s = getComputedStyle(document.body); return [s.backgroundColor, s.color];")
    lum = lambda c: sum(int(x) for x in re.findall(r"\d+", c)[:3])
    check("the dark theme is dark with light text", lum(bg) < 150 and lum(fg) > 500, (bg, fg))
    driver.set_window_size(1400, 900)
    driver.execute_script("document.querySelector('#traces').scrollIntoView();")
    time.sleep(0.5)
    driver.save_screenshot(os.path.join(shots, "web-dark-1400.png"))
    driver.execute_script("window.scrollTo(0, 0);")
    go("#/runs")
    wait(lambda: page_rows() or None, what="dark runs")
    shot_at("dark-runs", 1400)
    driver.execute_cdp_cmd("Emulation.setEmulatedMedia", {"features": [{"name": "prefers-color-scheme", "value": "light"}]})
    driver.set_window_size(1400, 900)
    # An operator cancels its own runs only: oscar's running run shows no Cancel to olga; olga's own does.
    theirs = api("POST", "/api/runs", OPERATOR2, {"spec": dict(spec, name="web-oscars", duration_s=30.0)})["run_ids"][0]
    mine = api("POST", "/api/runs", OPERATOR, {"spec": dict(spec, name="web-olgas", duration_s=30.0)})["run_ids"][0]
    go("#/")
    wait(lambda: len(driver.find_elements(By.CSS_SELECTOR, "#queue tr[data-run='%s'], #queue tr[data-run='%s']"
                                          % (theirs, mine))) == 2 or None, what="both runs in the queue")
    check("an operator sees Cancel on its own run only",
          not driver.find_elements(By.CSS_SELECTOR, "#queue tr[data-run='%s'] button.cancel" % theirs) and
          driver.find_elements(By.CSS_SELECTOR, "#queue tr[data-run='%s'] button.cancel" % mine),
          text_of(By.ID, "queue")[:400])
    api("POST", "/api/runs/%s/cancel" % theirs, OPERATOR2, {})
    api("POST", "/api/runs/%s/cancel" % mine, OPERATOR, {})
    errors = console_errors()
    check("no console error on the lists, downloads and themes", not errors, errors)

    # 8. A viewer follows the lab but cannot submit: the server's PERMISSION_DENIED shows on the page.
    driver.find_element(By.ID, "logout").click()
    # The login form shows once the logout's request has answered: wait for it rather than type into a hidden box.
    wait(lambda: driver.find_element(By.ID, "token").is_displayed() or None, what="the login form after logout")
    driver.find_element(By.ID, "token").send_keys(VIEWER)
    driver.find_element(By.ID, "login-button").click()
    wait(lambda: driver.find_elements(By.CSS_SELECTOR, "#session:not([hidden])") or None, what="viewer session")
    who = wait(lambda: "vic" in driver.find_element(By.ID, "session-text").text and
               driver.find_element(By.ID, "session-text").text, what="viewer in the header")
    check("the header shows the viewer and the role", bool(who) and "viewer" in who, who)
    # An operator's run running: the viewer sees it in the queue and on its page, without Cancel or Re-run.
    running = api("POST", "/api/runs", OPERATOR, {"spec": dict(spec, name="web-viewer-sees", duration_s=30.0)})["run_ids"][0]
    go("#/")
    wait(lambda: driver.find_elements(By.CSS_SELECTOR, "#queue tr[data-run='%s']" % running) or None, what="queue (viewer)")
    check("a viewer sees no Cancel in the queue", not driver.find_elements(By.CSS_SELECTOR, "#queue button.cancel"),
          text_of(By.ID, "queue")[:300])
    nav = [a.text for a in driver.find_elements(By.CSS_SELECTOR, "#nav a") if a.is_displayed()]
    check("a viewer's navigation has no Submit", "Submit" not in nav, nav)
    go("#/run/%s" % running)
    wait(lambda: driver.find_elements(By.CSS_SELECTOR, "#traces .live-count") or None, what="run page (viewer)")
    check("a viewer sees no Cancel or Re-run on a run", not driver.find_elements(By.CSS_SELECTOR, "#cancel, #rerun"),
          text_of(By.CSS_SELECTOR, "#main .actions"))
    go("#/submit")
    wait(lambda: driver.find_elements(By.ID, "spec") or None, what="spec editor (viewer)")
    button = driver.find_element(By.ID, "submit")
    check("a viewer's Submit is disabled with the reason", not button.is_enabled() and "operator role" in
          (button.get_attribute("title") or "") and driver.find_elements(By.ID, "role-notice"), button.get_attribute("title"))
    imp = driver.find_elements(By.ID, "import-button")
    check("a viewer's Import is disabled with the reason", imp and not imp[0].is_enabled() and
          "operator role" in (imp[0].get_attribute("title") or ""), imp[0].get_attribute("title") if imp else None)
    before = len(api("GET", "/api/runs?page_size=1000", VIEWER).get("runs", []))
    try:  # the service refuses the viewer whatever the page shows
        api("POST", "/api/runs", VIEWER, {"spec": spec})
        check("the service refuses a viewer's submission", False, "accepted")
    except urllib.error.HTTPError as e:
        check("the service refuses a viewer's submission", e.code == 403, e.code)
    check("nothing was queued for the viewer", len(api("GET", "/api/runs?page_size=1000", VIEWER).get("runs", [])) == before)
    errors = console_errors()
    check("no console error as a viewer", not errors, errors)

    # 9. The server goes away: a "disconnected — retrying" banner over the stale page, gone when it is back.
    go("#/")
    wait(lambda: driver.find_elements(By.CSS_SELECTOR, "#benches tr") or None, what="lab before the outage")
    api("POST", "/api/runs/%s/cancel" % running, OPERATOR, {})
    web_port = int(base.rsplit(":", 1)[1])
    cookie_before = session_cookie()
    proc.terminate()
    proc.wait(timeout=20)
    banner = wait(lambda: driver.find_element(By.ID, "disconnected").is_displayed() and
                  driver.find_element(By.ID, "disconnected").text, what="disconnected banner")
    check("a banner says the server is gone", bool(banner) and "Disconnected" in banner and "retrying" in banner, banner)
    check("no 'Failed to fetch' over the page", "Failed to fetch" not in text_of(By.ID, "flash"))
    shot_at("disconnected", 1024)
    config["web"]["listen_address"] = "127.0.0.1:%d" % web_port
    config["nights"]["cron"] = "0 2 * * *"
    with open(os.path.join(work, "server.json"), "w") as f:
        json.dump(config, f)
    proc = subprocess.Popen([server_bin, "--config", os.path.join(work, "server.json")], stderr=log,
                            stdout=subprocess.DEVNULL)
    gone = wait(lambda: not driver.find_element(By.ID, "disconnected").is_displayed() or None, timeout=30,
                what="banner cleared")
    check("the banner clears when the server is back", bool(gone))
    console_errors()  # the outage's failed requests are expected

    # 10. After the restart the page works without a reload (issue 37, point 4), in the same session (issue 39,
    # point 4: sessions are kept in the server's sessions file): the browser's cookie is the one it had, the page
    # did not log in again, and a live view (cookie-authorised) and a download work.
    after = api("POST", "/api/runs", OPERATOR, {"spec": dict(spec, name="web-after-restart", duration_s=20.0)})["run_ids"][0]
    go("#/run/%s" % after)
    live = wait(lambda: int(driver.find_element(By.CSS_SELECTOR, "#traces .live-count").get_attribute("data-samples")
                            or 0) > 0 or None, timeout=30, what="live samples after the restart")
    check("a live view works after the restart without a reload", bool(live),
          text_of(By.ID, "traces")[:300])
    status = driver.execute_async_script(
        "const done = arguments[arguments.length - 1];"
        "fetch('/api/runs/%s/trace.csv', {credentials: 'same-origin'}).then((r) => done(r.status), () => done(0));" % start_id)
    check("a download works after the restart without a reload", status == 200, status)
    cookie_after = session_cookie()
    check("the browser's session survived the restart (the same cookie, no new login)",
          bool(cookie_before) and cookie_after == cookie_before, (cookie_before, cookie_after))
    flash_now = text_of(By.ID, "flash")
    check("no gRPC words on the page after the restart", "UNAVAILABLE" not in flash_now and
          "authorization metadata" not in text_of(By.ID, "main"), flash_now)
    api("POST", "/api/runs/%s/cancel" % after, OPERATOR, {})

    # 11. The served batch report draws its charts in the browser under its own CSP (issue 34: the dashboard's CSP
    # blocked its inline scripts, so it drew none): the report's scripts are allowed by their hashes, nothing else.
    console_errors()
    driver.get(base + "/api/batches/%s/report.html" % batch)  # a navigation: the session cookie authorises it
    drawn = wait(lambda: driver.execute_script("return document.querySelectorAll('canvas, svg.plot').length") or None,
                 what="the report's charts")
    csp = [e for e in console_errors() if "Content Security Policy" in e or "Refused" in e]
    check("the served report draws its charts under its CSP", bool(drawn) and not csp, (drawn, csp))
except SystemExit:
    raise
except Exception as e:  # noqa: BLE001
    import traceback
    traceback.print_exc()
    check("the browser test ran to the end", False, repr(e))
finally:
    if driver is not None:
        driver.quit()
    proc.terminate()
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
print("%d failure(s), %.1f s" % (len(failures), time.time() - t_start))
sys.exit(1 if failures else 0)
