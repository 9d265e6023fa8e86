"""The package without a server: a private valvebench-server on the embedded emulator and a local store."""
import os
import time

import numpy as np
import pytest

import valvebench
from valvebench.v1 import spec_pb2

LAWS = ["hysteresis", "pi", "predictive", "fuzzy"]


@pytest.fixture(scope="module")
def comparison(local_client, repo):
    events = []
    batch = local_client.run(os.path.join(repo, "examples", "compare-current-controllers.json"), progress=events.append)
    return batch, events


def test_three_lines_give_the_four_laws_currents(comparison):
    batch, _ = comparison
    currents = batch.channel("i_A")
    assert list(currents.columns) == [law + " i_A" for law in LAWS]
    assert currents.index.name == "t_s"
    assert len(currents) == 5001                         # 0.1 s at 50 kHz, first sample at 0
    assert currents.attrs["units"] == {law + " i_A": "A" for law in LAWS}
    hold = currents.loc[0.02:0.1]
    # Every law holds the 0.5 A reference during the hold (docs/current-controllers.md): mean within 5 mA.
    assert np.all(np.abs(hold.mean() - 0.5) < 0.005), hold.mean()
    assert currents.attrs["conditions"]["pi i_A"] == {"supply_V": 24.0, "supply_pressure_Pa": 400000.0}


def test_progress_callback_sees_each_run_end(comparison):
    batch, events = comparison
    assert all(isinstance(e, valvebench.Progress) for e in events)
    finals = {e.run_id: e.status for e in events if e.status in ("done", "failed", "cancelled")}
    assert finals == {rid: "done" for rid in batch.run_ids}
    for rid in batch.run_ids:
        p = [e.progress for e in events if e.run_id == rid]
        assert p == sorted(p) and p[-1] == pytest.approx(1.0)


def test_trace_dataframe_has_units_spec_and_conditions(comparison):
    batch, _ = comparison
    run = batch["pi"]
    trace = run.trace()
    assert trace.units["i_A"] == "A" and trace.units["v_coil_V"] == "V" and trace.units["ref"] == "A"
    assert trace["t_s"][1] == pytest.approx(2e-5)
    df = trace.to_dataframe()
    for col in ("i_A", "v_coil_V", "x_m", "ref_A", "flow_kg_per_s", "gate"):
        assert col in df.columns, df.columns
    assert df.attrs["units"]["ref_A"] == "A" and df.attrs["units"]["x_m"] == "m"
    assert df.attrs["spec"]["controller"] == {"pi_current": {}}
    assert df.attrs["conditions"]["supply_V"] == 24.0
    assert df.attrs["run_id"] == run.id
    # The trace and the stored metric agree: mean current over the metric window.
    assert df.loc[0.02:0.1, "i_A"].mean() == pytest.approx(run.metrics["mean_current_A"], abs=2e-4)


def test_compare_table_has_units_in_column_names(comparison):
    batch, _ = comparison
    table = batch.compare().to_dataframe()
    assert sorted(table.index) == sorted(LAWS)
    assert "rmse_A" in table.columns and "energy_J" in table.columns and "effort_l2_V_sqrt_s" in table.columns
    assert table.attrs["units"]["rmse_A"] == "A"
    assert table["rank"].min() == 1
    best = table["rmse_A"].idxmin()
    assert table.loc[best, "rank"] == 1
    per_run = batch.metrics()
    assert per_run.loc["pi", "rmse_A"] == pytest.approx(table.loc["pi", "rmse_A"])


def test_list_get_and_stored_batch(local_client, comparison):
    batch, _ = comparison
    runs = local_client.list_runs(batch_id=batch.batch_id)
    assert sorted(r.id for r in runs) == sorted(batch.run_ids)
    assert all(r.status == "done" for r in runs)
    again = local_client.get_batch(batch.batch_id)
    assert [r.label for r in again] == LAWS
    assert local_client.list_runs(status="done", controller="pi_current", limit=1)[0].controller == "pi_current"
    with pytest.raises(valvebench.InvalidArgument, match="status: 'finished'"):
        local_client.list_runs(status="finished")


def test_spec_as_dict_and_as_message(local_client, repo):
    spec = {"name": "py-dict", "controller": {"open_loop_pwm": {"segments": [{"frequency_Hz": 0, "duty": 1}]}},
            "conditions": {"supply_V": 24}, "duration_s": 0.01, "recording": {"rate_Hz": 10000}}
    run = local_client.run(spec)[0]
    assert run.ok and run.name == "py-dict"
    assert len(run.trace()) == 101
    # What executing it measured, stored with the run: 10 ms of valve time, 101 samples; not paced, so no loop.
    assert run.execution is not None, run.proto
    assert run.execution["simulated_s"] == pytest.approx(0.01)
    assert run.execution["samples"] == 101
    assert run.execution["wall_s"] > 0
    assert "loop" not in run.execution
    assert run.execution["build"].startswith("valvebench ") and " sha256:" in run.execution["build"], run.execution
    assert local_client.get_run(run.id).execution == run.execution
    paced = local_client.run(dict(spec, name="py-paced", realtime=True))[0]  # 10 ms paced on the embedded bench
    assert paced.ok, paced.reason
    assert paced.execution["loop"]["ticks"] > 0, paced.execution
    assert 0 <= paced.execution["loop"]["jitter_p50_s"] <= paced.execution["loop"]["jitter_max_s"]
    msg = valvebench.load_spec(os.path.join(repo, "examples", "standard", "e1.json"))
    assert isinstance(msg, spec_pb2.ExperimentSpec)
    assert local_client.run(msg).ok


def test_errors_name_the_field(local_client):
    bad = {"name": "bad", "controller": {"pi_current": {}}, "conditions": {"supply_V": -1}, "duration_s": 0.01}
    with pytest.raises(valvebench.InvalidArgument) as e:
        local_client.submit(bad)
    assert "conditions.supply_V" in str(e.value) and e.value.code == "INVALID_ARGUMENT"
    with pytest.raises(valvebench.InvalidArgument, match="^spec: conditions.supply_volts: unknown field$"):
        local_client.submit({"name": "typo", "conditions": {"supply_volts": 24}})
    with pytest.raises(valvebench.InvalidArgument, match=r"^spec: sweep\[0\].values\[0\]: Couldn't parse float: a$"):
        local_client.submit({"name": "typo", "sweep": [{"field": "duration_s", "values": ["a"]}]})
    with pytest.raises(valvebench.InvalidArgument, match="cannot read the spec"):
        local_client.submit("/nonexistent/spec.json")
    with pytest.raises(valvebench.NotFound):
        local_client.get_run(987654)


def test_cancel_a_running_run(local_client):
    spec = {"name": "long", "controller": {"pi_current": {}}, "reference": {"constant": {"value": 0.5}},
            "conditions": {"supply_V": 24}, "duration_s": 30, "realtime": True, "recording": {"rate_Hz": 1000}}
    batch = local_client.submit(spec)
    rid = batch.run_ids[0]
    deadline = time.monotonic() + 10
    while local_client.get_run(rid).status != "running" and time.monotonic() < deadline:
        time.sleep(0.02)
    assert local_client.get_run(rid).status == "running"
    t0 = time.monotonic()
    local_client.cancel(rid, reason="py test")
    run = local_client.watch(rid, timeout_s=20)
    assert run.status == "cancelled" and "py test" in run.reason, (run, run.reason)
    assert time.monotonic() - t0 < 5                 # a 30 s realtime run, stopped at once
    with pytest.raises(valvebench.FailedPrecondition):
        local_client.cancel(rid)                      # already finished


def test_model_with_params_runs_on_its_own_bench(local_client):
    base = {"controller": {"open_loop_pwm": {"segments": [{"frequency_Hz": 0, "duty": 1}]}},
            "conditions": {"supply_V": 24}, "duration_s": 0.005, "recording": {"rate_Hz": 20000}}
    nominal = local_client.run(dict(base, name="R-nominal"))[0]
    other = valvebench.Client.local(db=local_client.db)   # shares the private server ...
    high_r = local_client.run(dict(base, name="R-high", bench={"model": {"preset": "taghizadeh2009",
                                                                       "params": {"R": 26.0}}}))[0]
    assert nominal.ok and high_r.ok
    assert other.get_run(high_r.id).ok                    # ... and follows it to its new port after the restart
    other.close()
    # Twice the resistance: the current rises more slowly, so less current at 5 ms.
    assert high_r.trace()["i_A"][-1] < 0.8 * nominal.trace()["i_A"][-1]
    with pytest.raises(valvebench.InvalidArgument, match=r"variants\[0\].bench.model"):
        local_client.submit(dict(base, name="v", variants=[{"name": "a", "bench": {"model": {"params": {"R": 1}}}}]))


def test_import_runs_from_arrays(local_client, shared):
    import csv
    import json
    p07 = os.path.join(shared, "gapbench", "practice", "p07")
    if not os.path.isdir(p07):
        pytest.skip("no ../shared/gapbench/practice/p07")
    manifest = json.load(open(os.path.join(p07, "manifest.json")))
    runs = []
    for r in manifest["runs"]:
        rows = list(csv.DictReader(open(os.path.join(p07, r["file"]))))
        t = np.array([float(x["t_s"]) for x in rows])
        runs.append({"id": r["id"], "supply_V": r["supply_V"], "supply_pressure_Pa": r.get("supply_pressure_Pa", 0),
                     "t_start_s": r.get("t_start_s", 0), "split": r.get("split", ""),
                     "sample_period_s": (t[-1] - t[0]) / (len(t) - 1),
                     "gate": [int(x["gate"]) for x in rows], "i_A": [float(x["i_A"]) for x in rows]})
    batch = local_client.import_runs("p07-arrays", runs, model=manifest["model"])
    assert len(batch) == len(manifest["runs"]) and all(r.ok for r in batch)
    assert "imported" in batch[0].tags
    bad = [dict(runs[0], gate=[2] + runs[0]["gate"][1:])]
    with pytest.raises(valvebench.InvalidArgument, match=r"runs\[0\].gate\[0\]"):
        local_client.import_runs("bad", bad)


def test_import_dataset_and_diagnose_stored_runs(local_client, shared):
    """benchctl's reader and the service's diagnosis (DiagnoseRuns) behind the Python calls: p07's answer is
    supply_resistance (labels.json)."""
    p07 = os.path.join(shared, "gapbench", "practice", "p07")
    if not os.path.isdir(p07):
        pytest.skip("no ../shared/gapbench/practice/p07")
    batch = local_client.import_dataset(p07)
    assert len(batch) == 12 and all("dataset:p07" in r.tags for r in batch)
    diagnosis = local_client.diagnose(batch=batch)
    assert diagnosis.verdict == "supply_resistance", diagnosis.verdict_reason
    # The service's DiagnoseRuns: its text report and the improved model come along.
    assert "supply_resistance" in diagnosis.report
    assert "supply_resistance" in diagnosis.improved_model_json
    ranking = diagnosis.ranking()
    assert ranking.index[0] == "supply_resistance"
    assert ranking.loc["supply_resistance", "params"]["supply_resistance.R_s"] == pytest.approx(0.8, rel=0.25)
    assert ranking.loc["supply_resistance", "holdout_rmse_after_A"] < ranking.loc["supply_resistance",
                                                                                  "holdout_rmse_before_A"]
    with pytest.raises(valvebench.InvalidArgument, match="does not exist"):
        local_client.diagnose(dataset="/nonexistent/dataset")


def test_benchctl_local_runs_share_the_store(local_client, repo):
    """benchctl run --local and the Python local mode record into the same store and see each other's runs."""
    import json
    import subprocess
    out = subprocess.run([valvebench.find_tool("benchctl"), "run", "--local",
                          os.path.join(repo, "examples", "compare-current-controllers.json"),
                          "--db", local_client.db, "--json"], capture_output=True, text=True, check=True).stdout
    made = json.loads(out)
    made = made if isinstance(made, list) else made.get("runs", made)
    batch_id = made[0]["batch_id"]
    batch = local_client.get_batch(batch_id)
    assert [r.label for r in batch] == ["hysteresis", "pi", "predictive", "fuzzy"]
    assert batch["pi"].metrics["rmse"] == pytest.approx(made[1]["metrics"]["rmse"])
    assert batch.channel("i_A").shape == (5001, 4)
    assert batch.compare().to_dataframe().loc["pi", "runs"] == 1


def test_one_private_server_per_store(local_client):
    """Clients of one process share the store's private server; another process is refused, naming the store."""
    import subprocess
    import sys
    with valvebench.Client.local(db=local_client.db) as second:
        assert second.server == local_client.server
        assert second.list_runs(limit=1)[0].id == local_client.list_runs(limit=1)[0].id
    local_client.list_runs(limit=1)                   # closing the second client left the server running
    proc = subprocess.run([sys.executable, "-c", "import valvebench; valvebench.Client.local(db=%r)" % local_client.db],
                          capture_output=True, text=True)
    assert proc.returncode != 0
    assert "local store %s: another process's private valvebench-server" % local_client.db in proc.stderr


def test_start_waits_for_benchctl_local_runs(tmp_path):
    """A server start re-queues the runs marked running; benchctl's in-flight run must not be one of them."""
    import json
    import subprocess
    db = str(tmp_path / "shared.db")
    spec = tmp_path / "slow.json"
    spec.write_text(json.dumps({"name": "slow", "controller": {"pi_current": {}},
                                "reference": {"constant": {"value": 0.5}}, "conditions": {"supply_V": 24},
                                "duration_s": 1.0, "realtime": True, "recording": {"rate_Hz": 1000}}))
    bc = subprocess.Popen([valvebench.find_tool("benchctl"), "run", "--local", str(spec), "--db", db],
                          stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:               # until benchctl's run is executing
        if os.path.exists(db) and valvebench.local.LocalServer._benchctl_running(type("S", (), {"db": db})()):
            break
        time.sleep(0.02)
    t0 = time.monotonic()
    with valvebench.Client.local(db=db) as c:
        waited = time.monotonic() - t0
        out, err = bc.communicate(timeout=20)
        assert bc.returncode == 0, err                # benchctl finished its run undisturbed
        run = c.list_runs(limit=1)[0]
        assert run.status == "done" and run.name == "slow", (run, run.reason)
    assert 0.2 < waited < 5, waited


def test_pandas_is_optional(local_client, repo):
    """Without pandas, numpy traces work and the DataFrame methods say what to install."""
    import subprocess
    import sys
    code = ("import sys; sys.modules['pandas'] = None\n"
            "import valvebench\n"
            "c = valvebench.Client(%r, %r)\n"
            "run = c.run(%r)[0]\n"
            "print(len(run.trace()['i_A']))\n"
            "try:\n    run.trace().to_dataframe()\nexcept valvebench.Unavailable as e:\n    print(e)\n"
            % (local_client.server, local_client.token, os.path.join(repo, "examples", "standard", "e1.json")))
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert int(lines[0]) > 1000 and "apt-get install python3-pandas" in lines[1], proc.stdout
