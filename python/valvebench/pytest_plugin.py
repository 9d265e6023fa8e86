"""pytest plugin: a ``bench`` fixture on the embedded emulator (or a server given on the command line),
helpers to run a spec and assert on metrics with tolerances, and the run ids in the JUnit XML.

Enabled by the package's pytest11 entry point when installed, or with ``-p valvebench.pytest_plugin``.

    def test_pi_holds_the_current(bench):
        batch = bench.run("examples/compare-current-controllers.json")
        bench.check(batch["pi"], "rmse", below=0.02)                 # A
        bench.check(batch["pi"], "mean_current_A", near=0.5, abs=0.01)

Options: --valvebench-server ADDR (default: a private server on the embedded emulator), --valvebench-token
(or $VALVEBENCH_TOKEN), --valvebench-db FILE (local store; default as benchctl --local). Every run a test makes
becomes a JUnit property ``valvebench_run`` = "<id> <name> <status> (<where stored>)", and a failing test's
report lists them, so a CI failure links to the stored run (benchctl show ID / export ID).
"""
import copy
import math

import pytest

from .client import Batch, Client, Run, load_spec
from .errors import InvalidArgument


def pytest_addoption(parser):
    group = parser.getgroup("valvebench")
    group.addoption("--valvebench-server", default=None,
                    help="bench server host:port (default: a private server on the embedded emulator)")
    group.addoption("--valvebench-token", default=None, help="bearer token (default $VALVEBENCH_TOKEN)")
    group.addoption("--valvebench-db", default=None,
                    help="local store of the emulated bench (default: $VALVEBENCH_DB or "
                         "~/.local/share/valvebench/local.db, as benchctl --local)")


@pytest.fixture(scope="session")
def valvebench_client(request):
    """One Client for the session: the server from --valvebench-server, else a private local server."""
    server = request.config.getoption("--valvebench-server")
    token = request.config.getoption("--valvebench-token")
    if server:
        client = Client(server, token)
    else:
        client = Client.local(db=request.config.getoption("--valvebench-db"))
    yield client
    client.close()


def pytest_report_header(config):
    server = config.getoption("--valvebench-server")
    if server:
        return "valvebench: server %s" % server
    return "valvebench: embedded emulator (private server), store %s" % (
        config.getoption("--valvebench-db") or "benchctl's default local store")


def _merge(base, over, path=""):
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(base.get(k), dict):
            _merge(base[k], v, path + k + ".")
        else:
            base[k] = copy.deepcopy(v)
    return base


class Bench:
    """What a test gets from the ``bench`` fixture: run(), check(), runs made so far, the Client."""

    def __init__(self, client, record_property):
        self.client = client
        self._record = record_property
        self.runs = []

    def run(self, spec, overrides=None, progress=None, timeout_s=600.0):
        """Runs a spec (dict, JSON file path or ExperimentSpec), with ``overrides`` merged into it (a dict in
        the spec's JSON form, e.g. {"conditions": {"supply_V": 12}}), and waits. Returns the Batch; every run
        is recorded for the JUnit XML."""
        if overrides:
            from google.protobuf import json_format
            base = json_format.MessageToDict(load_spec(spec), preserving_proto_field_name=True)
            spec = _merge(base, overrides)
        batch = self.client.submit(spec)
        for rid in batch.run_ids:  # recorded before waiting: a test that times out still names its runs
            self._record("valvebench_run_id", rid)
        batch.wait(progress=progress, timeout_s=timeout_s)
        for r in batch.runs:
            self.record(r)
        return batch

    def record(self, run):
        """Names a run in this test's JUnit properties (bench.run does it for its own runs; use it for runs
        made by a shared fixture)."""
        self.runs.append(run)
        self._record("valvebench_run", "%d %s %s (%s)" % (run.id, run.name, run.status, self.client.describe()))
        return run

    def check(self, run, metric, *, below=None, above=None, near=None, rel=None, abs=None):
        """Asserts on a finished run's metric: below/above bounds (inclusive) and/or near=value within
        max(rel * |value|, abs) (default: rel 1e-6). The message names the run, its stored location, the metric
        with its unit and the bound that failed. Returns the value."""
        if isinstance(run, Batch):
            if len(run.runs) != 1:
                raise InvalidArgument("check: a batch of %d runs; pass one run (batch['label'])" % len(run.runs))
            run = run.runs[0]
        if not isinstance(run, Run):
            raise InvalidArgument("check: expected a valvebench.Run, got %s" % type(run).__name__)
        if below is None and above is None and near is None:
            raise InvalidArgument("check: give below=, above= or near=")
        where = "run %d (%s) in %s" % (run.id, run.name, self.client.describe())
        if run.status != "done":
            pytest.fail("%s ended %s%s" % (where, run.status, ": " + run.reason if run.reason else ""), pytrace=False)
        unit = run.metric_unit(metric)
        if metric not in run.metrics:
            pytest.fail("%s: no metric '%s' (NaN or unknown; has: %s)" % (where, metric, ", ".join(sorted(run.metrics))),
                        pytrace=False)
        v = run.metrics[metric]
        u = " " + unit if unit and unit != "1" else ""
        problems = []
        if below is not None and not v <= below:
            problems.append("expected <= %.6g%s" % (below, u))
        if above is not None and not v >= above:
            problems.append("expected >= %.6g%s" % (above, u))
        if near is not None:
            tol = max((1e-6 if rel is None and abs is None else (rel or 0.0)) * math.fabs(near), abs or 0.0)
            if not math.fabs(v - near) <= tol:
                problems.append("expected %.6g%s +/- %.3g%s (off by %.3g%s)" % (near, u, tol, u, v - near, u))
        if problems:
            pytest.fail("%s: %s = %.6g%s, %s" % (where, metric, v, u, "; ".join(problems)), pytrace=False)
        return v


@pytest.fixture
def bench(valvebench_client, request):
    """An emulated bench (or the --valvebench-server): run specs, check metrics; runs land in the JUnit XML."""
    # The item's user_properties are what record_property writes, without its warning under xunit2.
    return Bench(valvebench_client, lambda name, value: request.node.user_properties.append((name, value)))


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    report = outcome.get_result()
    if report.when == "call" and report.failed:
        lines = ["%s = %s" % (k, v) for k, v in item.user_properties if k == "valvebench_run"]
        if lines:
            report.sections.append(("valvebench runs", "\n".join(lines)))
