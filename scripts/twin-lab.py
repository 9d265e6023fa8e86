#!/usr/bin/env python3
"""The bench twin's measure (issue 38, docs/track.md "A simulated lab"): six emulated benches live N nights in
one server start (--simulate-nights), each checked before every night; three valves change (a resistance ramp,
a relaxing spring, shorted turns), three stay as they are; on two nights the suite's PI law is worse (its
proportional gain cut tenfold: the code regresses). Afterwards it reads the nights and each bench's tracking
from the server and prints, per drift, the night it reaches 3 sigma of its parameter's reference and the night
it was flagged (with the parameter), the flags on the clean benches, and each regressed night's cause against
the truth.

    scripts/twin-lab.py BUILD_DIR [--nights 60] [--work DIR] [--json OUT] [--baseline-night K] [--model JSON]

    scripts/twin-lab.py BUILD_DIR --evaluate-only --work DIR   (the same report from a lab already lived)

The code regression is made by swapping the suite's hold spec between nights: the server reads the suite after
it queues a night's health checks, so the swap happens once the night before has loaded its own suite (its log
line "suite ... batch"). Truth per regressed case: "code" for the PI hold (the law whose gain was cut) on a code
night, else "valve" (only a changed valve can make an unchanged code regress). A night's truth: "code" or
"valve" when all its regressed cases agree, "both" otherwise, which the twin can only call "undetermined"
("both changed"); it is counted right when its cause is the truth ("undetermined" for "both").

The nights compare with examples/suites/ci-baseline.json (made elsewhere: its runs, and the build that ran them,
are not this server's). With --baseline-night K the lab does what a lab would: once night K is stored, it sets
the baseline from that night's suite batch on this server (`benchctl baseline set --batch`) and the nights after
compare with it; each regressed case then knows whether its spec and build are the baseline's (docs/track.md,
"The build recorded with each run").

--model '{"params": {...}, "effects": [...]}' gives every bench another valve than the preset (a ModelSpec merged
over {"preset": "taghizadeh2009"}); the examples' baseline is then not this valve's, so use --baseline-night.
"""
import argparse
import datetime
import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
TOKEN = "twin-lab-viewer"
OPERATOR_TOKEN = "twin-lab-operator"

# Each drift: the bench, the model parameter the emulator changes, the tracked quantities it moves (what the
# current can see: docs/track.md point 2), its form. Chosen as a lab meets them: a corroding connector (R up
# 0.5 % a night), a relaxing spring (k down 1 % a night: the preload F0 = k (x_min + delta) falls with it),
# shorted turns (N down 3 % at once: L0 and L1 fall by about 6 %). The hold (gap/hold.h) measures the winding's
# resistance (R_hold) and the held coil's inductance (L_hold) beside the switch-on's identification, and its
# drop-out the current at which the plunger lets go (i_dropout: the spring's force at the stop against the pull
# per ampere squared, so a relaxing spring lowers it and shorted turns raise it).
DRIFTS = [
    {"bench": "emu-1", "parameter": "R", "step": 0.0, "per_night": 0.005, "from_night": 20, "moves": ["R", "R_hold"]},
    {"bench": "emu-2", "parameter": "k", "step": 0.0, "per_night": -0.01, "from_night": 30,
     "moves": ["F0*x_max", "k*x_max^2", "i_dropout"]},
    {"bench": "emu-3", "parameter": "N", "step": -0.03, "per_night": 0.0, "from_night": 40,
     "moves": ["L0", "L1", "L_hold", "i_dropout"]},
]
CLEAN = ["emu-4", "emu-5", "emu-6"]
CODE_NIGHTS = [25, 45]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("build_dir")
    ap.add_argument("--nights", type=int, default=60)
    ap.add_argument("--work", default="/tmp/vb-twin-lab")
    ap.add_argument("--json", default="")
    ap.add_argument("--evaluate-only", action="store_true", help="read the nights of the lab in --work again")
    ap.add_argument("--baseline-night", type=int, default=0,
                    help="set the baseline from this night's suite batch once it is stored (0: the example's)")
    ap.add_argument("--model", default="", help="a ModelSpec (JSON) merged over the preset for every bench")
    a = ap.parse_args()
    if a.evaluate_only:
        return evaluate_again(a)
    server_bin = os.path.join(a.build_dir, "bin", "valvebench-server")
    benchctl = os.path.join(a.build_dir, "bin", "benchctl")
    shutil.rmtree(a.work, ignore_errors=True)
    os.makedirs(a.work)
    suites = os.path.join(ROOT, "examples", "suites")
    shutil.copy(os.path.join(suites, "ci.json"), a.work)
    good = open(os.path.join(suites, "ci-current-hold.json")).read()
    law = good.find('"pi_current": {}', good.find('"name": "pi"'))
    assert law >= 0, "examples/suites/ci-current-hold.json changed: no pi variant"
    worse = good[:law] + '"pi_current": {"kp_V_per_A": 37.7}' + good[law + len('"pi_current": {}'):]
    hold = os.path.join(a.work, "ci-current-hold.json")

    def use(text):
        with open(hold + ".new", "w") as f:
            f.write(text)
        os.replace(hold + ".new", hold)

    use(good)
    health = {"supply_V": [24, 20], "supply_pressure_Pa": [100000, 250000, 400000]}
    benches = []
    for k in range(1, 7):
        name = "emu-%d" % k
        model = {"preset": "taghizadeh2009"}
        model.update(json.loads(a.model) if a.model else {})
        b = {"name": name, "kind": "emulated", "model": model, "health": health,
             "current_noise_A": 0.002}
        d = [{kk: x[kk] for kk in ("parameter", "step", "per_night", "from_night")} for x in DRIFTS if x["bench"] == name]
        if d:
            b["drift"] = d
        benches.append(b)
    baseline_file = os.path.join(a.work, "baseline.json")
    shutil.copy(os.path.join(suites, "ci-baseline.json"), baseline_file)
    config = {"listen_address": "127.0.0.1:0", "database_path": os.path.join(a.work, "runs.db"), "benches": benches,
              "tokens": [{"user": "v", "role": "viewer", "token_sha256": hashlib.sha256(TOKEN.encode()).hexdigest()},
                         {"user": "o", "role": "operator",
                          "token_sha256": hashlib.sha256(OPERATOR_TOKEN.encode()).hexdigest()}],
              "nights": {"cron": "0 2 * * *", "suite_file": os.path.join(a.work, "ci.json"),
                         "baseline_file": baseline_file, "timezone": "UTC"}}
    with open(os.path.join(a.work, "server.json"), "w") as f:
        json.dump(config, f, indent=1)

    today = datetime.datetime.now(datetime.timezone.utc).date()
    dates = [(today - datetime.timedelta(days=a.nights - n)).isoformat() for n in range(1, a.nights + 1)]
    log_path = os.path.join(a.work, "server.log")
    log = open(log_path, "w")
    t0 = time.time()
    proc = subprocess.Popen([server_bin, "--config", os.path.join(a.work, "server.json"), "--simulate-nights",
                             str(a.nights)], stderr=log, stdout=subprocess.DEVNULL)
    addr = None
    swapped = set()
    rebased = a.baseline_night <= 0
    done = 0
    try:
        while True:
            time.sleep(0.2)
            text = open(log_path).read()
            if addr is None:
                m = re.search(r"listening on (\S+) ", text)
                addr = m.group(1) if m else None
            # The suite of night n loaded: the next night's code goes in place now.
            for n in range(1, a.nights):
                if n in swapped or ("night %s: suite" % dates[n - 1]) not in text:
                    continue
                use(worse if (n + 1) in CODE_NIGHTS else good)
                swapped.add(n)
            stored = len(re.findall(r"night \d{4}-\d\d-\d\d: (passed|regressed|error)", text))
            if stored != done:
                done = stored
                print("%5.0f s: %d of %d nights" % (time.time() - t0, done, a.nights), flush=True)
            if not rebased and done >= a.baseline_night:
                set_baseline(benchctl, addr, dates[a.baseline_night - 1], baseline_file)
                rebased = True
            if done >= a.nights:
                break
            if proc.poll() is not None:
                sys.exit("valvebench-server exited: see " + log_path)
        elapsed = time.time() - t0
        nights, health_j = read_lab(benchctl, addr)
    finally:
        proc.terminate()
        proc.wait(timeout=60)
    return report_out(evaluate(nights, health_j, dates, elapsed), a.json)


def set_baseline(benchctl, addr, date, path):
    """The baseline from night `date`'s suite batch on this server, written into the file the nights read."""
    listed = subprocess.run([benchctl, "nights", "--json", "--limit", "1000", "--server", addr, "--token", TOKEN],
                            capture_output=True, text=True, timeout=600)
    night = [n for n in json.loads(listed.stdout) if n.get("date") == date]
    if not night:
        sys.exit("night %s is not stored: %s" % (date, listed.stderr[:500]))
    r = subprocess.run([benchctl, "baseline", "set", "lab-night-" + date, "--batch", str(night[0]["batch_id"]),
                        "--json", "--server", addr, "--token", OPERATOR_TOKEN],
                       capture_output=True, text=True, timeout=600)
    if r.returncode != 0:
        sys.exit("benchctl baseline set: " + (r.stderr or r.stdout)[:500])
    with open(path + ".new", "w") as f:
        f.write(r.stdout[r.stdout.find("{"):])
    os.replace(path + ".new", path)
    print("baseline set from night %s (batch %d)" % (date, night[0]["batch_id"]), flush=True)


def read_lab(benchctl, addr):
    """The lab's nights (oldest first) and every bench's tracking, as the server keeps them."""
    def out(*args):
        r = subprocess.run([benchctl] + list(args) + ["--json", "--server", addr, "--token", TOKEN],
                           capture_output=True, text=True, timeout=600)
        try:
            return json.loads(r.stdout)
        except json.JSONDecodeError:
            sys.exit("benchctl %s: %s" % (" ".join(args), (r.stderr or r.stdout)[:500]))
    return list(reversed(out("nights", "--limit", "1000"))), out("health")


def report_out(report, path):
    if path:
        with open(path, "w") as f:
            json.dump(report, f, indent=1)
    return 0


def evaluate_again(a):
    """The lab in a.work, read again through a server started on its database (no night is run)."""
    server_bin = os.path.join(a.build_dir, "bin", "valvebench-server")
    benchctl = os.path.join(a.build_dir, "bin", "benchctl")
    config = json.load(open(os.path.join(a.work, "server.json")))
    config.pop("nights", None)
    for b in config["benches"]:
        b.pop("health", None)
    path = os.path.join(a.work, "server-evaluate.json")
    with open(path, "w") as f:
        json.dump(config, f)
    log_path = os.path.join(a.work, "server-evaluate.log")
    proc = subprocess.Popen([server_bin, "--config", path], stderr=open(log_path, "w"), stdout=subprocess.DEVNULL)
    try:
        addr = None
        for _ in range(300):
            m = re.search(r"listening on (\S+) ", open(log_path).read())
            if m:
                addr = m.group(1)
                break
            time.sleep(0.1)
        if addr is None:
            sys.exit("valvebench-server did not start: see " + log_path)
        nights, health_j = read_lab(benchctl, addr)
    finally:
        proc.terminate()
        proc.wait(timeout=60)
    return report_out(evaluate(nights, health_j, [n["date"] for n in nights], float("nan")), a.json)


def evaluate(nights, health_j, dates, elapsed):
    by_bench = {b["bench"]: b for b in health_j.get("benches", [])}
    if elapsed == elapsed:  # not NaN: lived now (--evaluate-only reads a lab lived before)
        print("\n%d nights lived in %.0f s (%.1f s a night)" % (len(nights), elapsed, elapsed / max(1, len(nights))))
    report = {"nights": len(nights), "elapsed_s": elapsed, "drifts": [], "clean": [], "regressed_nights": []}
    print("\nDrifts (3 sigma: the night the true change first exceeds 3 sigma of the parameter's reference):")
    for d in DRIFTS:
        b = by_bench.get(d["bench"], {})
        params = {p["parameter"]: p for p in b.get("parameters", [])}
        flags = b.get("flags", [])
        row = {"bench": d["bench"], "drift": "%s %+g step %+g/night from night %d" % (d["parameter"], d["step"], d["per_night"], d["from_night"])}
        # The night the true relative change passes 3 sigma (relative) of each moved parameter's reference, the
        # first of them; the relative size a parameter moves by per relative change of the model parameter is
        # taken from the parameter's own values after the flag (so the 3-sigma night is the measured series').
        first3 = None
        for name in d["moves"]:
            p = params.get(name)
            if not p or not p.get("center") or not p.get("sigma"):
                continue
            rel_sigma = abs(p["sigma"] / p["center"])
            vals = [v["value"] for v in p["values"]]
            base = p["center"]
            for n in range(d["from_night"], len(vals) + 1):
                if vals[n - 1] is not None and abs(vals[n - 1] - base) / abs(base) > 3 * rel_sigma:
                    first3 = n if first3 is None else min(first3, n)
                    break
        row["night_3_sigma"] = first3
        mine = [f for f in flags if f["parameter"] in d["moves"]]
        other = [f for f in flags if f["parameter"] not in d["moves"]]
        row["flagged"] = [{"parameter": f["parameter"], "night": dates.index(f["session"]) + 1,
                           "since": dates.index(f["since"]) + 1 if f.get("since") in dates else None,
                           "change_relative": f.get("change_relative")} for f in mine]
        row["other_flags"] = [{"parameter": f["parameter"], "night": dates.index(f["session"]) + 1} for f in other]
        fn = min((x["night"] for x in row["flagged"]), default=None)
        row["delay_nights"] = None if fn is None or first3 is None else fn - first3
        row["within_5"] = row["delay_nights"] is not None and row["delay_nights"] <= 5
        report["drifts"].append(row)
        print("  %s %-40s 3 sigma at night %s; flagged %s; delay %s; other flags %s" % (
            d["bench"], row["drift"], first3,
            ", ".join("%s night %d (since %s, %+.1f %%)" % (x["parameter"], x["night"], x["since"], 100 * (x["change_relative"] or 0))
                      for x in row["flagged"]) or "never", row["delay_nights"],
            ", ".join("%s night %d" % (x["parameter"], x["night"]) for x in row["other_flags"]) or "none"))
    print("\nClean benches:")
    for name in CLEAN:
        b = by_bench.get(name, {})
        flags = b.get("flags", [])
        report["clean"].append({"bench": name, "nights": len(b.get("sessions", [])),
                                "flags": [{"parameter": f["parameter"], "night": dates.index(f["session"]) + 1} for f in flags]})
        print("  %s: %d nights, %s" % (name, len(b.get("sessions", [])),
                                        ", ".join("%s flagged night %d" % (f["parameter"], dates.index(f["session"]) + 1)
                                                  for f in flags) or "no flag"))
    print("\nRegressed nights (truth per case: the PI hold on code nights %s is code, any other case valve):" % CODE_NIGHTS)
    right = 0
    for k, n in enumerate(nights, 1):
        if n.get("verdict") != "regressed":
            continue
        cases = n.get("regressed_cases", [])
        kinds = {"code" if (k in CODE_NIGHTS and c.startswith("hold/pi")) else "valve" for c in cases}
        truth = kinds.pop() if len(kinds) == 1 else "both"
        ok = n.get("cause") == (truth if truth != "both" else "undetermined")
        right += ok
        report["regressed_nights"].append({"night": k, "date": n.get("date"), "truth": truth, "cause": n.get("cause"),
                                           "reason": n.get("cause_reason"), "cases": n.get("regressed_cases", []),
                                           "correct": ok})
        print("  night %2d %s: cause %-12s truth %-5s %s  (%s) %s" % (k, n.get("date"), n.get("cause"), truth,
                                                                   "ok" if ok else "WRONG", ", ".join(n.get("regressed_cases", [])),
                                                                   n.get("cause_reason", "")[:160]))
    missing = [k for k in CODE_NIGHTS if k <= len(nights) and nights[k - 1].get("verdict") != "regressed"]
    total = len(report["regressed_nights"])
    print("\n  %d of %d regressed nights attributed correctly; code nights that did not regress: %s" % (right, total, missing or "none"))
    report["attributed_correctly"] = right
    report["code_nights_not_regressed"] = missing
    return report


if __name__ == "__main__":
    sys.exit(main())
