#!/usr/bin/env bash
# The bring-your-own-valve workflow (docs/real-data.md) on any readings CSV of the akita11 layout:
#   device,supply_V,amp_feedback_ohm,temp_C,stroke_mm,pwm_Hz,on_time_s,sample,t_after_edge_s,v_mV_mean,v_mV_sd,repeats
#
#   examples/realdata/akita11/run.sh CSV OUTDIR
#
# For every held stroke of every device in the file:
#   1. identify the coil from scratch on the coldest session: R, L, the sense chain's offset and the freewheel
#      diode's drop, each in a wide box (a global search, then a local fit);
#   2. identify it again on the hottest session;
#   3. diagnose the hottest session against the coldest one (--reference): which effect explains what changed.
# Writes OUTDIR/datasets/ (valve-runs/2), OUTDIR/<session>.identify.json, OUTDIR/<hot>.diagnose.json and
# OUTDIR/summary.json:
#   {"device": ..., "strokes": [{"stroke_mm", "R_cold_ohm", "R_hot_ohm", "L_cold_H", "offset_A", "verdict",
#                                "closed", ...}], "seconds": ...}
# Environment: BENCHCTL (default: the build tree's), PARAMS (the identified parameters and their boxes).
set -euo pipefail
if [ $# -ne 2 ]; then
  echo "usage: $0 READINGS.csv OUTDIR" >&2
  exit 2
fi
csv=$1
out=$2
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
benchctl=${BENCHCTL:-$here/../../../build/bin/benchctl}
params=${PARAMS:-R=1:1000,L=0.0001:10,sensor_offset.offset_A=-0.2:0.2,driver.diode_drop_V=0:1.5}
start=$(date +%s.%N)

mkdir -p "$out"
"$benchctl" convert "$csv" "$out/datasets" --json > "$out/sessions.json"

# One line per (device, stroke): "device<TAB>stroke_mm<TAB>coldest dir<TAB>hottest dir".
python3 - "$out/sessions.json" > "$out/pairs.tsv" <<'PY'
import json, sys
sessions = json.load(open(sys.argv[1]))
groups = {}
for s in sessions:
    groups.setdefault((s["device"], s["stroke_m"]), []).append(s)
for (device, stroke_m), ss in sorted(groups.items()):
    ss.sort(key=lambda s: s["temp_C"])
    print(f'{device}\t{stroke_m * 1e3:g}\t{ss[0]["directory"]}\t{ss[-1]["directory"]}')
PY

while IFS=$'\t' read -r device stroke cold hot; do
  c=$(basename "$cold")
  h=$(basename "$hot")
  echo "== $device, plunger at $stroke mm: $c (reference) vs $h" >&2
  "$benchctl" identify "$cold" --params "$params" --json > "$out/$c.identify.json"
  "$benchctl" identify "$hot" --params "$params" --json > "$out/$h.identify.json"
  if [ "$cold" != "$hot" ]; then
    "$benchctl" diagnose "$hot" --reference "$cold" --reference-params "$params" --json-out "$out/$h.diagnose.json" \
      > "$out/$h.diagnose.txt"
  fi
done < "$out/pairs.tsv"

end=$(date +%s.%N)
python3 - "$out" "$start" "$end" <<'PY'
import json, os, sys
out, start, end = sys.argv[1], float(sys.argv[2]), float(sys.argv[3])
devices = {}
for line in open(os.path.join(out, "pairs.tsv")):
    device, stroke, cold, hot = line.rstrip("\n").split("\t")
    c, h = os.path.basename(cold), os.path.basename(hot)
    ic = json.load(open(os.path.join(out, c + ".identify.json")))
    ih = json.load(open(os.path.join(out, h + ".identify.json")))
    row = {"stroke_mm": float(stroke),
           "R_cold_ohm": ic["params"]["R"]["value"], "R_hot_ohm": ih["params"]["R"]["value"],
           "L_cold_H": ic["params"]["L"]["value"], "offset_A": ic["params"]["sensor_offset.offset_A"]["value"],
           "diode_drop_V": ic["params"]["driver.diode_drop_V"]["value"],
           "fit_rmse_cold_A": ic["fit_rmse_A"], "fit_rmse_hot_A": ih["fit_rmse_A"],
           "cold": c, "hot": h, "verdict": None, "closed": None}
    row["R_hot_over_cold"] = row["R_hot_ohm"] / row["R_cold_ohm"]
    dpath = os.path.join(out, h + ".diagnose.json")
    if cold != hot and os.path.exists(dpath):
        d = json.load(open(dpath))
        row["verdict"] = d["verdict"]
        row["closed"] = d.get("how_far", {}).get("closed")
        row["confusable"] = d.get("confusable", [])
    devices.setdefault(device, []).append(row)
summary = [{"device": dev, "strokes": sorted(rows, key=lambda r: r["stroke_mm"])} for dev, rows in devices.items()]
result = summary[0] if len(summary) == 1 else {"devices": summary}
result["seconds"] = round(end - start, 2)
json.dump(result, open(os.path.join(out, "summary.json"), "w"), indent=1)
for s in summary:
    print(f'{s["device"]}: stroke [mm]  R cold [ohm]  R hot [ohm]  hot/cold  L cold [mH]  offset [mA]  verdict (closed)')
    for r in s["strokes"]:
        closed = "" if r["closed"] is None else f' ({100 * r["closed"]:.0f} %)'
        print(f'  {r["stroke_mm"]:12.2f}  {r["R_cold_ohm"]:12.2f}  {r["R_hot_ohm"]:11.2f}  {r["R_hot_over_cold"]:8.3f}'
              f'  {1e3 * r["L_cold_H"]:11.1f}  {1e3 * r["offset_A"]:11.1f}  {r["verdict"]}{closed}')
print(f'{result["seconds"]} s; summary in {os.path.join(out, "summary.json")}')
PY
