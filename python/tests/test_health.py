"""client.health(): the bench twin's tracking as the server keeps it (docs/track.md "On the server"), on a real
valvebench-server that lives eight nights at start (--simulate-nights) with a bench whose coil resistance is 15 %
higher from night 6."""
import hashlib
import re
import signal
import time

import pytest

import valvebench

from conftest import SOURCE_DIR, VIEWER, start_server


@pytest.fixture(scope="module")
def twin_server(tmp_path_factory):
    work = tmp_path_factory.mktemp("twin")
    suites = SOURCE_DIR + "/examples/suites/"
    config = {"listen_address": "127.0.0.1:0", "database_path": "runs.db",
              "benches": [{"name": "emu-a", "kind": "emulated", "model": {"preset": "taghizadeh2009"},
                           "health": {"supply_V": [24, 20], "supply_pressure_Pa": [100000, 250000, 400000]},
                           "current_noise_A": 0.002,
                           "drift": [{"parameter": "R", "step": 0.15, "from_night": 6}]}],
              "nights": {"cron": "0 2 * * *", "suite_file": suites + "ci.json",
                         "baseline_file": suites + "ci-baseline.json"},
              "tokens": [{"user": "view", "role": "viewer", "token_sha256": hashlib.sha256(VIEWER.encode()).hexdigest()}]}
    proc, log, address = start_server(work, config, "--simulate-nights", "8")
    # Eight nights stored: the eighth night's line in the log.
    stored = 0
    for _ in range(3000):
        log.seek(0)
        stored = len(re.findall(r"night \S+: (passed|regressed|error) ", log.read()))
        if stored >= 8:
            break
        time.sleep(0.1)
    assert stored >= 8, "the server stored %d nights in 300 s" % stored
    yield address
    proc.send_signal(signal.SIGTERM)
    proc.wait(timeout=30)


def test_health_is_a_dataframe_with_the_flagged_parameter(twin_server):
    c = valvebench.Client(twin_server, VIEWER)
    df = c.health("emu-a")
    assert list(df.columns) == ["bench", "night", "parameter", "unit", "value", "sigma", "z", "lower_limit",
                                "upper_limit", "flagged"]
    nights = sorted(df["night"].unique())
    assert len(nights) == 8
    r = df[df["parameter"] == "R"].sort_values("night")
    assert list(r["unit"].unique()) == ["ohm"]
    # R 15 % higher from night 6, flagged by night 8 (the reference is the first five nights; a gross change adds
    # about 2.5, then 4 and more a night to the CUSUM, docs/track.md "Outliers") and not before night 6.
    assert r["value"].iloc[5] / r["value"].iloc[:5].mean() == pytest.approx(1.15, abs=0.02)
    assert not r["flagged"].iloc[:5].any()
    # The hold measures the same winding (R_hold, the more precise: flagged first on the same night when both are).
    h = df[df["parameter"] == "R_hold"].sort_values("night")
    assert h["value"].iloc[5] / h["value"].iloc[:5].mean() == pytest.approx(1.15, abs=0.005)
    flags = df.attrs["flags"]
    assert flags and flags[0]["parameter"] in ("R", "R_hold") and flags[0]["since"] == nights[5], flags
    assert flags[0]["change_relative"] == pytest.approx(0.15, abs=0.02)
    # Every bench with checks: the same one here.
    assert set(c.health()["bench"]) == {"emu-a"}
    with pytest.raises(valvebench.Error) as e:
        c.health("emu-z")
    assert e.value.code == "NOT_FOUND"
