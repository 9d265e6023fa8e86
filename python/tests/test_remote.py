"""The same package against a real valvebench-server on loopback, found through VALVEBENCH_SERVER/TOKEN."""
import os

import pytest

import valvebench
from conftest import OPERATOR, VIEWER


@pytest.fixture
def remote(remote_server, monkeypatch):
    monkeypatch.setenv("VALVEBENCH_SERVER", remote_server)
    monkeypatch.setenv("VALVEBENCH_TOKEN", OPERATOR)
    with valvebench.Client() as c:
        yield c


def test_client_reads_the_environment_and_runs_remotely(remote, remote_server, repo):
    assert not remote.is_local and remote.server == remote_server
    batch = remote.run(os.path.join(repo, "examples", "compare-current-controllers.json"))
    assert batch.ok and [r.label for r in batch] == ["hysteresis", "pi", "predictive", "fuzzy"]
    assert {r.bench for r in batch} <= {"emu-a", "emu-b"}
    assert all(r.submitter == "op" for r in batch)
    currents = batch.channel("i_A")
    assert currents.shape == (5001, 4)
    assert remote.compare(run_ids=batch.run_ids).to_dataframe().loc["pi", "runs"] == 1
    assert [b["name"] for b in remote.benches()] == ["emu-a", "emu-b"]


def test_roles_and_tokens_become_exceptions(remote_server, repo):
    spec = os.path.join(repo, "examples", "standard", "e1.json")
    with valvebench.Client(remote_server, VIEWER) as viewer:
        viewer.list_runs(limit=1)                                   # viewers read
        with pytest.raises(valvebench.PermissionDenied):
            viewer.submit(spec)
    with valvebench.Client(remote_server, "wrong-token") as stranger:
        with pytest.raises(valvebench.Unauthenticated):
            stranger.list_runs()


def test_unreachable_server_is_unavailable():
    with valvebench.Client("127.0.0.1:1", "t", timeout_s=1.0) as c:
        with pytest.raises(valvebench.Unavailable):
            c.list_runs()


def test_local_false_without_a_server_is_refused(monkeypatch):
    monkeypatch.delenv("VALVEBENCH_SERVER", raising=False)
    with pytest.raises(valvebench.InvalidArgument, match="server: none given"):
        valvebench.Client(local=False)


def test_live_samples_carry_the_gate_duty(remote):
    """A 20 kHz PWM at duty 0.3 watched at 50 samples a second: each live sample's duty is the gate's mean over
    its interval (0.3), where the kept instants' gate levels are 0 or 1 (issue 37: the live view drew a fast
    PWM as solid "on")."""
    spec = {"name": "py-live-duty",
            "bench": {"kind": "emulated", "model": {"preset": "taghizadeh2009"}, "driver": {"kind": "low_side_flyback"}},
            "conditions": {"supply_V": 15.0, "supply_pressure_Pa": 0.0},
            "controller": {"open_loop_pwm": {"segments": [{"start_s": 0.0, "frequency_Hz": 20000.0, "duty": 0.3}]}},
            "duration_s": 1.5, "realtime": True, "recording": {"rate_Hz": 50000.0}}
    batch = remote.submit(spec)
    events = []
    run = remote.watch(batch.run_ids[0], progress=events.append, sample_rate_Hz=50.0)
    assert run.status == "done", run.reason
    duty = [d for p in events for d in p.duty]
    gates = {s[1] for p in events for s in p.samples}
    assert len(duty) >= 20, len(duty)                      # about 1.5 s at 50 per second, watched from its start
    assert all(abs(d - 0.3) < 0.02 for d in duty[1:]), duty   # the first interval may start mid-period
    assert gates <= {0, 1}
    assert all(p.dropped_samples == 0 for p in events)     # an idle server keeps up
