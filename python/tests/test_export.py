"""benchctl export --hdf5/--mat, read back with h5py and scipy.io: channels with units, spec, conditions."""
import json
import os
import subprocess

import numpy as np
import pytest

import valvebench

h5py = pytest.importorskip("h5py")
scipy_io = pytest.importorskip("scipy.io")


@pytest.fixture(scope="module")
def exported(local_client, repo, tmp_path_factory):
    run = local_client.run(os.path.join(repo, "examples", "compare-current-controllers.json"))["predictive"]
    out = tmp_path_factory.mktemp("export")
    h5, mat, csv = str(out / "run.h5"), str(out / "run.mat"), str(out / "run.csv")
    subprocess.run([valvebench.find_tool("benchctl"), "export", str(run.id), "--hdf5", h5, "--mat", mat,
                    "--csv", csv, "--server", local_client.server, "--token", local_client.token], check=True)
    return run, run.trace(), h5, mat, csv


def test_hdf5_channels_units_spec_conditions(exported):
    run, trace, h5, _, _ = exported
    with h5py.File(h5, "r") as f:
        assert f.attrs["format"] == "valvebench-run/1"
        assert f.attrs["run_id"] == run.id and f.attrs["controller"] == "predictive_current"
        assert json.loads(f.attrs["spec_json"])["controller"] == {"predictive_current": {}}
        assert set(f["channels"]) == set(trace.channels)
        for name, values in trace.channels.items():
            np.testing.assert_array_equal(f["channels"][name][()], values)
            # One unit table: the C++ writer and the Python package agree on every channel.
            assert f["channels"][name].attrs["units"] == trace.units[name], name
        assert f["conditions/supply_V"][()] == 24.0 and f["conditions/supply_V"].attrs["units"] == "V"
        assert f["conditions/supply_pressure_Pa"][()] == 4e5
        assert f["metrics/rmse"][()] == pytest.approx(run.metrics["rmse"])
        assert f["metrics/rmse"].attrs["units"] == "A"
        for m in run.metrics:
            assert f["metrics"][m].attrs["units"] == run.metric_unit(m), m


def test_mat_struct(exported):
    run, trace, _, mat, _ = exported
    m = scipy_io.loadmat(mat, simplify_cells=True)["vbrun"]
    assert m["run_id"] == run.id and m["name"] == run.name
    assert json.loads(m["spec_json"])["conditions"]["supply_V"] == 24
    for name, values in trace.channels.items():
        np.testing.assert_array_equal(np.ravel(m["channels"][name]), values)
        assert m["units"][name] == trace.units[name], name
    assert m["conditions"]["supply_pressure_Pa"] == 4e5
    assert m["metrics"]["energy_J"] == pytest.approx(run.metrics["energy_J"])
    assert m["metric_units"]["rmse"] == "A"


def test_csv_still_written_beside(exported):
    _, trace, _, _, csv = exported
    with open(csv) as f:
        assert f.readline().strip().split(",") == list(trace.channels)


def test_export_needs_a_format(local_client):
    proc = subprocess.run([valvebench.find_tool("benchctl"), "export", "1", "--server", local_client.server,
                           "--token", local_client.token], capture_output=True, text=True)
    assert proc.returncode == 2 and "--hdf5" in proc.stderr


def test_client_export_writes_the_same_files(local_client, exported, tmp_path):
    run, trace, _, _, _ = exported
    h5, mat = tmp_path / "c.h5", tmp_path / "c.mat"
    assert local_client.export(run.id, hdf5=h5, mat=mat) == [str(h5), str(mat)]
    with h5py.File(h5, "r") as f:
        np.testing.assert_array_equal(f["channels/i_A"][()], trace["i_A"])
    assert scipy_io.loadmat(str(mat), simplify_cells=True)["vbrun"]["run_id"] == run.id
    with pytest.raises(valvebench.InvalidArgument, match="give hdf5="):
        local_client.export(run.id)
    with pytest.raises(valvebench.InvalidArgument, match="run 987654"):
        local_client.export(987654, hdf5=tmp_path / "none.h5")
