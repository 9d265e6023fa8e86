"""valvebench.Client: submit specs, watch runs, fetch traces as numpy/pandas, compare, cancel, import, diagnose.

One code path: a remote valvebench-server (``server``/``VALVEBENCH_SERVER``) or, without one, a private server
on the embedded emulator and the local store (valvebench.local). Every call has a deadline; every failure is a
valvebench.Error whose message names the field (``conditions.supply_V: must be > 0, got -1``).
"""
import json
import os
import re
import subprocess
import time

import grpc
import numpy as np
from google.protobuf import json_format

from . import units
from .errors import Error, InvalidArgument, RunFailed, Unavailable, from_grpc
from . import local as _local
from .local import find_tool
from .v1 import api_pb2, api_pb2_grpc, spec_pb2

STATUS_NAMES = {api_pb2.QUEUED: "queued", api_pb2.RUNNING: "running", api_pb2.DONE: "done",
                api_pb2.FAILED: "failed", api_pb2.CANCELLED: "cancelled", api_pb2.INTERRUPTED: "interrupted",
                api_pb2.RUN_STATUS_UNSPECIFIED: "unspecified"}
ENDED = ("done", "failed", "cancelled")


def _pandas():
    try:
        import pandas
    except ImportError as e:  # pragma: no cover - depends on the machine
        raise Unavailable("pandas is not installed (Debian: apt-get install python3-pandas); "
                          "the numpy forms (Trace.channels, Comparison.rows) work without it") from e
    return pandas


def _field_message(text):
    """protobuf's JSON parse error as 'field.path: what is wrong' (the field path first, as the server says it)."""
    m = re.search(r'has no field named "([^"]+)" at "([^"]+)"', text)
    if m:
        path = m.group(2).split(".", 1)[1] + "." if "." in m.group(2) else ""
        return "%s%s: unknown field" % (path, m.group(1))
    m = re.search(r"([^:]+: [^\n]*?) at ([A-Za-z]+\.[\w.\[\]]+?)\.*$", text.splitlines()[-1])
    if m and "." in m.group(2):
        return "%s: %s" % (m.group(2).split(".", 1)[1], m.group(1).rsplit("field: ", 1)[-1])
    return text


def load_spec(spec):
    """An ExperimentSpec from a dict, a JSON file path, a JSON string, or the message itself. Unknown fields are
    errors (a typo must not fall back to a default); the message names the field."""
    if isinstance(spec, spec_pb2.ExperimentSpec):
        return spec
    msg = spec_pb2.ExperimentSpec()
    where = "spec"
    try:
        if isinstance(spec, dict):
            json_format.ParseDict(spec, msg)
        elif isinstance(spec, (str, os.PathLike)):
            text = str(spec)
            if not text.lstrip().startswith("{"):
                where = text
                try:
                    with open(text) as f:
                        text = f.read()
                except OSError as e:
                    raise InvalidArgument("%s: cannot read the spec: %s" % (where, e.strerror)) from e
            json_format.Parse(text, msg)
        else:
            raise InvalidArgument("spec: expected a dict, a JSON file path or an ExperimentSpec, got %s"
                                  % type(spec).__name__)
    except json_format.ParseError as e:
        raise InvalidArgument("%s: %s" % (where, _field_message(str(e)))) from e
    return msg


class Progress:
    """One WatchRun event: run_id, status ('queued', 'running', 'done', ...), progress 0..1, reason, and the
    live downsampled samples (t_s, gate, i_A, x_m, ref) when asked for; ``duty`` has each sample's gate duty
    over the interval since the previous one (a PWM thinned to the asked rate reads as its duty, not as the
    level of the kept instant), and ``dropped_samples`` counts the live samples the server could not deliver
    to this watch so far (its buffer was full or the watcher fell behind; thinning is not a loss)."""

    __slots__ = ("run_id", "status", "progress", "reason", "samples", "duty", "dropped_samples")

    def __init__(self, ev):
        self.run_id = ev.run_id
        self.status = STATUS_NAMES.get(ev.status, "unspecified")
        self.progress = ev.progress
        self.reason = ev.reason
        self.samples = [(s.t_s, s.gate, s.i_A, s.x_m, s.ref) for s in ev.samples]
        self.duty = [s.duty for s in ev.samples]
        self.dropped_samples = ev.dropped_samples

    def __repr__(self):
        return "Progress(run %d %s %.0f%%)" % (self.run_id, self.status, 100 * self.progress)


class Run:
    """A stored run: id, batch_id, name, label (name without the batch's common prefix), controller, bench,
    status, reason, progress, tags, metrics (dict, SI units as in docs/metrics.md), spec (dict),
    conditions (supply_V, supply_pressure_Pa), the history of status changes and execution (what executing it
    measured; None for a run that did not execute)."""

    def __init__(self, client, proto):
        self._client = client
        self.proto = proto
        self.id = proto.id
        self.batch_id = proto.batch_id
        self.name = proto.name
        self.label = proto.name
        self.controller = proto.controller
        self.bench = proto.bench
        self.submitter = proto.submitter
        self.status = STATUS_NAMES.get(proto.status, "unspecified")
        self.reason = proto.reason
        self.progress = proto.progress
        self.tags = list(proto.tags)
        self.metrics = dict(proto.metrics)
        self.spec = json_format.MessageToDict(proto.spec, preserving_proto_field_name=True)
        self.conditions = {"supply_V": proto.spec.conditions.supply_V,
                           "supply_pressure_Pa": proto.spec.conditions.supply_pressure_Pa}
        self.history = [(STATUS_NAMES.get(h.status, "?"), h.at_unix_s, h.reason) for h in proto.history]
        self.submitted_unix_s = proto.submitted_unix_s
        self.started_unix_s = proto.started_unix_s
        self.finished_unix_s = proto.finished_unix_s
        # What executing it measured, stored with the run (None: it did not execute): wall_s, simulated_s,
        # samples, control_ticks, metrics_from_trajectory, and for a paced run "loop" (ticks, overruns,
        # jitter_p50_s, jitter_p99_s, jitter_max_s) and "build" (which build executed it, when known), as
        # benchctl show prints them.
        self.execution = None
        if proto.HasField("execution"):
            e = proto.execution
            self.execution = {"wall_s": e.wall_s, "simulated_s": e.simulated_s, "samples": e.samples,
                              "control_ticks": e.control_ticks,
                              "metrics_from_trajectory": e.metrics_from_trajectory}
            if e.build:
                self.execution["build"] = e.build
            if e.HasField("loop"):
                self.execution["loop"] = {"ticks": e.loop.ticks, "overruns": e.loop.overruns,
                                          "jitter_p50_s": e.loop.jitter_p50_s, "jitter_p99_s": e.loop.jitter_p99_s,
                                          "jitter_max_s": e.loop.jitter_max_s}

    @property
    def ok(self):
        return self.status == "done"

    @property
    def ended(self):
        return self.status in ENDED

    def metric(self, name):
        """A metric's value; KeyError naming the run and the metrics it has when absent (NaN metrics are absent)."""
        if name not in self.metrics:
            raise KeyError("run %d (%s): no metric '%s' (has: %s)"
                           % (self.id, self.name, name, ", ".join(sorted(self.metrics)) or "none"))
        return self.metrics[name]

    def metric_unit(self, name):
        return units.metric_unit(name, self.controller)

    def trace(self):
        """The recorded trace (valvebench.Trace: numpy channels, to_dataframe())."""
        return self._client.trace(self.id, run=self)

    def refresh(self):
        return self._client.get_run(self.id)

    def metrics_text(self):
        """The metrics one a line with unit and SI prefix, as `benchctl show` prints them ("rmse  953.3 \u00b5A")."""
        return "\n".join("%-20s %s" % (k, units.format_quantity(v, units.metric_unit(k, self.controller)))
                         for k, v in self.metrics.items())

    def __repr__(self):
        return "Run(%d %s [%s] %s)" % (self.id, self.name, self.controller, self.status)

    def __str__(self):
        return repr(self) + ("\n" + self.metrics_text() if self.metrics else "")


class Trace:
    """A run's trace: ``channels`` maps channel names (t_s, gate, v_coil_V, i_A, x_m, ...) to float64 numpy arrays
    of equal length; ``units`` maps each to its SI unit; ``run`` is the Run (spec, conditions, metrics)."""

    def __init__(self, run, t0_s, sample_period_s, channels):
        self.run = run
        self.t0_s = t0_s
        self.sample_period_s = sample_period_s
        self.channels = channels
        controller = run.controller if run is not None else ""
        self.units = {c: units.channel_unit(c, controller) for c in channels}

    def __getitem__(self, channel):
        try:
            return self.channels[channel]
        except KeyError:
            raise KeyError("trace: no channel '%s' (has: %s)" % (channel, ", ".join(self.channels))) from None

    def __len__(self):
        return len(next(iter(self.channels.values()))) if self.channels else 0

    def to_dataframe(self):
        """pandas DataFrame indexed by t_s; columns are the channel names, which carry their unit (i_A, v_coil_V,
        x_m; ``ref`` becomes ref_A or ref_m by the controller). ``df.attrs`` holds units (column -> unit),
        run_id, name, controller, spec (dict), conditions and metrics."""
        pd = _pandas()
        controller = self.run.controller if self.run is not None else ""
        cols = {}
        col_units = {}
        for name, values in self.channels.items():
            if name == "t_s":
                continue
            col = units.channel_column(name, controller)
            cols[col] = values
            col_units[col] = self.units[name]
        t = self.channels.get("t_s")
        if t is None:
            t = self.t0_s + self.sample_period_s * np.arange(len(self))
        df = pd.DataFrame(cols, index=pd.Index(t, name="t_s"))
        df.attrs["units"] = dict(col_units, t_s="s")
        if self.run is not None:
            df.attrs.update(run_id=self.run.id, name=self.run.name, controller=self.run.controller,
                            bench=self.run.bench, status=self.run.status, spec=self.run.spec,
                            conditions=self.run.conditions, metrics=self.run.metrics)
        return df


class Comparison:
    """CompareRuns: rows ranked by RMSE with effort beside it and the Pareto-optimal laws marked. ``rows`` is a
    list of dicts (name, rank, controller, runs, failed, pareto, metrics: {name: (mean, spread, n)})."""

    def __init__(self, proto):
        self.proto = proto
        self.rank_metric = proto.rank_metric
        self.effort_metric = proto.effort_metric
        self.columns = list(proto.columns)
        self.rows = [{"name": r.name, "rank": r.rank, "controller": r.controller, "runs": r.runs,
                      "failed": r.failed, "pareto": r.pareto,
                      "metrics": {k: (v.mean, v.spread, v.n) for k, v in r.metrics.items()}} for r in proto.rows]

    def to_dataframe(self, spread=False):
        """One row per compared group (index: name without the common batch prefix, 'pi'), columns rank, controller, runs, failed, pareto, then each
        metric's mean with its unit in the column name (rmse_A, effort_l2_V_sqrt_s, energy_J, ...); with
        spread=True also '<column>_sd' (standard deviation over repeats). ``df.attrs['units']`` maps columns to
        units."""
        pd = _pandas()
        records, col_units = [], {}
        prefix = _common_prefix([row["name"] for row in self.rows])
        for row in self.rows:
            rec = {k: row[k] for k in ("name", "rank", "controller", "runs", "failed", "pareto")}
            rec["name"] = row["name"][len(prefix):] or row["name"]
            for m in self.columns:
                col = units.metric_column(m, row["controller"])
                col_units[col] = units.metric_unit(m, row["controller"])
                mean, sd, n = row["metrics"].get(m, (float("nan"), float("nan"), 0))
                rec[col] = mean if n > 0 else float("nan")
                if spread:
                    rec[col + "_sd"] = sd if n > 0 else float("nan")
                    col_units[col + "_sd"] = col_units[col]
            records.append(rec)
        df = pd.DataFrame.from_records(records)
        if len(df):
            df = df.set_index("name")
        df.attrs["units"] = col_units
        df.attrs["rank_metric"] = self.rank_metric
        df.attrs["effort_metric"] = self.effort_metric
        return df


def _common_prefix(names):
    if len(names) < 2:
        return ""
    prefix = os.path.commonprefix(names)
    cut = prefix.rfind("/")
    return prefix[:cut + 1] if cut >= 0 else ""


class Batch:
    """The runs of one submission: batch_id, run_ids, runs (Run objects, fetched when waited for)."""

    def __init__(self, client, batch_id, run_ids, runs=None):
        self._client = client
        self.batch_id = batch_id
        self.run_ids = list(run_ids)
        self.runs = list(runs) if runs is not None else []
        self._label()

    def _label(self):
        prefix = _common_prefix([r.name for r in self.runs])
        for r in self.runs:
            r.label = r.name[len(prefix):] or r.name

    def wait(self, progress=None, timeout_s=None):
        """Follows every run until it ends; progress(Progress) is called on each event. Returns self."""
        self.runs = [self._client.watch(rid, progress=progress, timeout_s=timeout_s) for rid in self.run_ids]
        self._label()
        return self

    def __iter__(self):
        return iter(self.runs)

    def __len__(self):
        return len(self.run_ids)

    def __getitem__(self, key):
        """runs by position or by label ('pi') / full name."""
        if isinstance(key, int):
            return self.runs[key]
        for r in self.runs:
            if key in (r.label, r.name):
                return r
        raise KeyError("batch %d: no run '%s' (has: %s)" % (self.batch_id, key, ", ".join(r.label for r in self.runs)))

    @property
    def ok(self):
        return bool(self.runs) and all(r.ok for r in self.runs)

    def raise_for_status(self):
        bad = [r for r in self.runs if not r.ok]
        if bad:
            raise RunFailed("; ".join("run %d (%s): %s%s" % (r.id, r.name, r.status, ": " + r.reason if r.reason else "")
                                      for r in bad))
        return self

    def compare(self):
        return self._client.compare(batch_id=self.batch_id)

    def traces(self):
        return {r.label: r.trace() for r in self.runs}

    def channel(self, channel="i_A"):
        """One channel of every run side by side: a DataFrame indexed by t_s with one column per run,
        '<label> <channel>' (e.g. 'pi i_A'); attrs: units, run_ids, spec of each run, conditions."""
        pd = _pandas()
        frames, col_units, run_ids, specs, conditions = [], {}, {}, {}, {}
        for r in self.runs:
            tr = r.trace()
            col = "%s %s" % (r.label, units.channel_column(channel, r.controller))
            frames.append(pd.Series(tr[channel], index=pd.Index(tr["t_s"], name="t_s"), name=col))
            col_units[col] = tr.units[channel]
            run_ids[col], specs[col], conditions[col] = r.id, r.spec, r.conditions
        df = pd.concat(frames, axis=1) if frames else pd.DataFrame()
        df.attrs.update(units=col_units, channel=channel, batch_id=self.batch_id, run_ids=run_ids, specs=specs,
                        conditions=conditions)
        return df

    def metrics(self):
        """One row per run (index: label), metric columns with units in their names (rmse_A, energy_J, ...)."""
        pd = _pandas()
        records, col_units = [], {}
        for r in self.runs:
            rec = {"label": r.label, "run_id": r.id, "status": r.status, "controller": r.controller}
            for m, v in sorted(r.metrics.items()):
                col = units.metric_column(m, r.controller)
                rec[col] = v
                col_units[col] = units.metric_unit(m, r.controller)
            records.append(rec)
        df = pd.DataFrame.from_records(records)
        if len(df):
            df = df.set_index("label")
        df.attrs["units"] = col_units
        return df

    def __repr__(self):
        return "Batch(%d: runs %s)" % (self.batch_id, ", ".join(map(str, self.run_ids)))


class RunList(list):
    """What list_runs returns: the runs (a list), plus how many matched the filters in all (`total`), how many
    of those are not in the list (`more`), the token that continues the listing (`next_page_token`, "" on the
    last page) and its order (`order_by`). Its repr ends with how many were left out, so a cut list says so."""

    def __init__(self, runs, total=0, next_page_token="", order_by="submitted desc"):
        super().__init__(runs)
        self.total = max(int(total), len(self))
        self.next_page_token = next_page_token
        self.order_by = order_by

    @property
    def more(self):
        """How many matching runs are not in this list (0 when it holds them all)."""
        return self.total - len(self)

    @property
    def truncated(self):
        return self.more > 0

    def __repr__(self):
        base = list.__repr__(self)
        if self.more > 0:
            return "%s  # %d of %d runs (%s); %d more: list_runs(limit=None) or page_token=" % (
                base, len(self), self.total, self.order_by, self.more)
        return base


class Queue:
    """What queue() returns: the server's queue view (GetQueue), the one `benchctl queue` prints and the web
    dashboard's Lab page shows. `running` and `queued` are lists of (Run, position, eta_s): position 0 for a
    running run, 1 for the run claimed next, ...; eta_s the seconds until it should end (None when unknown).
    `benches` are the bench dicts the estimate replays the claims on (each run only on the benches that can run it), `live_benches` their count, `at_unix_s` when
    the estimate was made."""

    def __init__(self, client, proto):
        def entries(items):
            return [(Run(client, q.run), q.position, q.eta_s if q.eta_s >= 0 else None) for q in items]
        self.running = entries(proto.running)
        self.queued = entries(proto.queued)
        self.benches = [json_format.MessageToDict(b, preserving_proto_field_name=True) for b in proto.benches]
        self.live_benches = proto.live_benches
        self.at_unix_s = proto.at_unix_s

    def __len__(self):
        return len(self.running) + len(self.queued)

    def to_dataframe(self):
        """One row per run (running first, then by position): id, name, status, position, eta_s, bench,
        submitter, priority."""
        pd = _pandas()
        rows = [{"id": r.id, "name": r.name, "status": r.status, "position": pos, "eta_s": eta,
                 "bench": r.bench, "submitter": r.submitter, "priority": r.proto.priority}
                for r, pos, eta in self.running + self.queued]
        return pd.DataFrame(rows, columns=["id", "name", "status", "position", "eta_s", "bench", "submitter",
                                           "priority"]).set_index("id")

    def __repr__(self):
        return "<valvebench.Queue %d running, %d queued on %d live bench(es)>" % (
            len(self.running), len(self.queued), self.live_benches)


class Client:
    """A valvebench server, remote or private.

    Client(server=None, token=None): ``server`` (host:port or unix:PATH) defaults to $VALVEBENCH_SERVER and
    ``token`` to $VALVEBENCH_TOKEN. With no server at all (or local=True), a private valvebench-server runs on
    the embedded emulator and the local store (``db``, default as benchctl --local: $VALVEBENCH_DB or
    ~/.local/share/valvebench/local.db) until close(). Use as a context manager to close it.
    """

    def __init__(self, server=None, token=None, *, local=None, db=None, tls_ca=None, timeout_s=30.0):
        if db is not None and server is None and local is None:
            local = True  # a store file only means something in local mode
        if server is None and local is not True:
            server = os.environ.get("VALVEBENCH_SERVER") or None
        if token is None:
            token = os.environ.get("VALVEBENCH_TOKEN", "")
        self.timeout_s = timeout_s
        self._local = None
        if local is False and server is None:
            raise InvalidArgument("server: none given (argument or VALVEBENCH_SERVER) and local=False")
        if local or server is None:
            self._local = _local.acquire(db)
            server, token = self._local.address, self._local.token
        self.token = token
        self.tls_ca = tls_ca
        self._channel = None
        self._connect(server)
        self._md = [("authorization", "Bearer " + token)] if token else []

    def _connect(self, server):
        if self._channel is not None:
            self._channel.close()
        self.server = server
        options = [("grpc.max_receive_message_length", 64 << 20), ("grpc.max_send_message_length", 64 << 20)]
        if self.tls_ca:
            with open(self.tls_ca, "rb") as f:
                creds = grpc.ssl_channel_credentials(root_certificates=f.read())
            self._channel = grpc.secure_channel(server, creds, options=options)
        else:
            self._channel = grpc.insecure_channel(server, options=options)
        self._stub = api_pb2_grpc.BenchServiceStub(self._channel)

    @classmethod
    def local(cls, db=None, **kw):
        """A private server on the embedded emulator and the local store (``db``)."""
        return cls(local=True, db=db, **kw)

    @property
    def is_local(self):
        return self._local is not None

    @property
    def db(self):
        """The local store file (local mode), else None."""
        return self._local.db if self._local else None

    def describe(self):
        """Where runs are stored, for people and for JUnit properties: 'local store FILE' or 'server ADDR'."""
        return ("local store " + self._local.db) if self._local else ("server " + self.server)

    def close(self):
        """Closes the channel; in local mode the private server stops when the process's last client on that
        store closes (or at exit)."""
        self._channel.close()
        if self._local is not None:
            _local.release(self._local)
            self._local = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # -- calls -------------------------------------------------------------------------------------------

    @property
    def _api(self):
        """The stub, reconnected if the private server restarted on another port (a bench for a new model,
        possibly added through another client of the same store)."""
        if self._local is not None and self._local.address != self.server:
            self._connect(self._local.address)
        return self._stub

    def _call(self, method, request, context="", timeout_s=None):
        try:
            return method(request, metadata=self._md, timeout=timeout_s or self.timeout_s)
        except grpc.RpcError as e:
            raise from_grpc(e, context) from None

    def _prepare(self, spec):
        """Local mode: pin a spec whose model has params or effects to a private bench running that model (the
        server runs a bench's configured model, docs/server.md). Per-variant models and sweeps over the model
        cannot be pinned and are refused, naming the field."""
        if self._local is None:
            return spec
        for k, v in enumerate(spec.variants):
            if v.HasField("bench") and v.bench.HasField("model"):
                raise InvalidArgument("variants[%d].bench.model: a model per variant is not supported in the "
                                      "Python local mode; use one spec per model (or benchctl run --local)" % k)
        for k, ax in enumerate(spec.sweep):
            if ax.field.startswith("bench.model"):
                raise InvalidArgument("sweep[%d].field: '%s': sweeping the model is not supported in the Python "
                                      "local mode (or benchctl run --local)" % (k, ax.field))
        if spec.bench.kind not in ("", "emulated") or spec.bench.name:
            return spec
        model = json_format.MessageToDict(spec.bench.model, preserving_proto_field_name=True)
        name = self._local.bench_for_model(model)  # may restart the server on a new port: _api follows
        if name.startswith("model-"):
            spec = spec_pb2.ExperimentSpec.FromString(spec.SerializeToString())
            spec.bench.name = name
        return spec

    def submit(self, spec, batch_name=""):
        """Queues a spec (dict, JSON file path, or ExperimentSpec); variants, sweeps and repeats expand into a
        batch. Returns the Batch without waiting (Batch.wait, Client.watch)."""
        msg = self._prepare(load_spec(spec))
        # The server's message as it words it: the field path first (docs/server.md).
        resp = self._call(self._api.SubmitRun, api_pb2.SubmitRunRequest(spec=msg, batch_name=batch_name))
        return Batch(self, resp.batch_id, resp.run_ids)

    def run(self, spec, progress=None, timeout_s=None, batch_name=""):
        """Submits and waits for every run; progress(Progress) is called on each event. Returns the Batch (its
        runs finished; failed runs are returned too: see Batch.ok / raise_for_status)."""
        return self.submit(spec, batch_name=batch_name).wait(progress=progress, timeout_s=timeout_s)

    def watch(self, run_id, progress=None, timeout_s=None, sample_rate_Hz=0.0):
        """Follows a run until it ends (progress(Progress) on each event); returns the finished Run. With
        sample_rate_Hz > 0 the events carry live downsampled samples."""
        req = api_pb2.WatchRunRequest(run_id=run_id, sample_rate_Hz=sample_rate_Hz)
        call = self._api.WatchRun(req, metadata=self._md, timeout=timeout_s or 24 * 3600.0)
        try:
            for ev in call:
                p = Progress(ev)
                if progress is not None:
                    progress(p)
                if p.status in ENDED:
                    break
        except grpc.RpcError as e:
            raise from_grpc(e, "run %d" % run_id) from None
        finally:
            call.cancel()  # the stream ends with the run; do not leave it to the garbage collector
        return self.get_run(run_id)

    def get_run(self, run_id):
        return Run(self, self._call(self._api.GetRun, api_pb2.GetRunRequest(run_id=run_id)))

    def get_batch(self, batch_id):
        """A stored batch with its runs (e.g. one made by benchctl run --local or another client)."""
        runs = self.list_runs(batch_id=batch_id, limit=None)
        runs.sort(key=lambda r: r.id)
        full = [self.get_run(r.id) for r in runs]
        return Batch(self, batch_id, [r.id for r in full], full)

    def list_runs(self, status=None, tag="", batch_id=0, controller="", bench="", submitter="", name="",
                  submitted_after=0.0, submitted_before=0.0, order_by="", limit=100, page_token=""):
        """Runs matching every filter given (without spec and history: get_run has them), newest first unless
        order_by says otherwise ("FIELD" or "FIELD desc", FIELD one of id, submitted, started, finished, duration,
        name, status, bench, controller, submitter). name matches runs whose name contains it; submitted_after and
        submitted_before are unix seconds. At most `limit` runs (None = every page).

        Returns a RunList: a list that also says how many runs matched (`total`), how many were left out
        (`more`) and where to continue (`next_page_token`, for page_token=); its repr says when it was cut."""
        code = 0
        if status:
            code = api_pb2.RunStatus.Value(status.upper()) if status.upper() in api_pb2.RunStatus.keys() else None
            if code is None:
                raise InvalidArgument("status: '%s' is not one of queued, running, done, failed, cancelled, "
                                      "interrupted" % status)
        if limit is not None and (isinstance(limit, bool) or not isinstance(limit, int) or limit < 1):
            raise InvalidArgument("limit: must be a positive integer or None (every run), got %r" % (limit,))
        out, token, total = [], page_token, 0
        while True:
            page = 1000 if limit is None else min(1000, max(1, limit - len(out)))
            req = api_pb2.ListRunsRequest(status=code, tag=tag, batch_id=batch_id, controller=controller,
                                          bench=bench, submitter=submitter, name=name,
                                          submitted_after_unix_s=submitted_after,
                                          submitted_before_unix_s=submitted_before, order_by=order_by,
                                          page_size=page, page_token=token)
            resp = self._call(self._api.ListRuns, req)
            out.extend(Run(self, r) for r in resp.runs)
            token, total = resp.next_page_token, resp.total_size
            if not token or (limit is not None and len(out) >= limit):
                return RunList(out, total=total, next_page_token=token, order_by=order_by or "submitted desc")

    def queue(self):
        """The queue as the server sees it (GetQueue): running runs and queued ones in claim order, with
        positions and ETAs (valvebench.Queue; to_dataframe())."""
        return Queue(self, self._call(self._api.GetQueue, api_pb2.GetQueueRequest()))

    def cancel(self, run_id, reason=""):
        return Run(self, self._call(self._api.CancelRun, api_pb2.CancelRunRequest(run_id=run_id, reason=reason),
                                    context="run %d" % run_id))

    def trace(self, run_id, run=None):
        """The recorded trace of a finished run as numpy arrays (valvebench.Trace)."""
        if run is None:
            run = self.get_run(run_id)
        channels, parts, t0, dt, total = None, [], 0.0, 0.0, 0
        try:
            for chunk in self._api.GetTrace(api_pb2.GetTraceRequest(run_id=run_id), metadata=self._md,
                                             timeout=max(60.0, self.timeout_s)):
                if channels is None:
                    channels, t0, dt, total = list(chunk.channels), chunk.t0_s, chunk.sample_period_s, chunk.total_samples
                data = np.frombuffer(chunk.data, dtype="<f8")
                if data.size != chunk.samples * len(channels):
                    raise Error("run %d: trace chunk %d holds %d values, expected %d samples x %d channels"
                                % (run_id, chunk.index, data.size, chunk.samples, len(channels)), code="DATA_LOSS")
                parts.append(data.reshape(len(channels), chunk.samples))
        except grpc.RpcError as e:
            raise from_grpc(e, "run %d" % run_id) from None
        if channels is None:
            return Trace(run, 0.0, 0.0, {})
        data = np.concatenate(parts, axis=1) if parts else np.zeros((len(channels), 0))
        if total and data.shape[1] != total:
            raise Error("run %d: trace has %d samples, the server announced %d" % (run_id, data.shape[1], total),
                        code="DATA_LOSS")
        return Trace(run, t0, dt, {c: np.ascontiguousarray(data[k]) for k, c in enumerate(channels)})

    def compare(self, batch_id=0, run_ids=()):
        """CompareRuns on a batch or on runs: valvebench.Comparison (to_dataframe() with units)."""
        req = api_pb2.CompareRunsRequest(batch_id=batch_id or 0, run_ids=list(run_ids))
        return Comparison(self._call(self._api.CompareRuns, req))

    def health(self, bench=""):
        """The bench twin (GetBenchHealth; docs/track.md "On the server"): each checked bench's valve parameters night
        by night, as the server identified them after each night's health check and tracked them with a
        self-starting CUSUM. A pandas DataFrame, one row per bench, night and parameter: bench, night, parameter,
        unit, value, sigma, z (NaN: in the reference), lower_limit, upper_limit (the reference's mean -+ 3 sigma),
        flagged (True on the night the parameter was flagged). Its attrs hold "flags" (one dict per flag: bench,
        night, parameter, direction, change_relative, z, since, drift_per_night, meaning) and "notes".
        bench="" takes every bench with checks stored; an unknown bench raises NOT_FOUND."""
        resp = self._call(self._api.GetBenchHealth, api_pb2.GetBenchHealthRequest(bench=bench),
                          context="bench %s" % bench if bench else "")
        pd = _pandas()
        rows, flags, notes = [], [], []
        for b in resp.benches:
            for p in b.parameters:
                for k, night in enumerate(b.nights):
                    rows.append({"bench": b.bench, "night": night, "parameter": p.name, "unit": p.unit,
                                 "value": p.value[k] if k < len(p.value) else float("nan"),
                                 "sigma": p.sigma[k] if k < len(p.sigma) else float("nan"),
                                 "z": p.z[k] if k < len(p.z) else float("nan"),
                                 "lower_limit": p.lower_limit, "upper_limit": p.upper_limit,
                                 "flagged": night == p.flagged_night})
            for f in b.flags:
                flags.append({"bench": b.bench, "night": f.night, "parameter": f.parameter, "unit": f.unit,
                              "direction": f.direction, "change": f.change, "change_relative": f.change_relative,
                              "z": f.z, "since": f.since, "drift_per_night": f.drift_per_night, "meaning": f.meaning})
            notes.extend("%s: %s" % (b.bench, n) for n in b.notes)
        df = pd.DataFrame(rows, columns=["bench", "night", "parameter", "unit", "value", "sigma", "z", "lower_limit",
                                         "upper_limit", "flagged"])
        df.attrs["flags"] = flags
        df.attrs["notes"] = notes
        return df

    def benches(self):
        """The server's benches as dicts (name, kind, driver, model, max_supply_V, busy, ...)."""
        resp = self._call(self._api.ListBenches, api_pb2.ListBenchesRequest())
        return [json_format.MessageToDict(b, preserving_proto_field_name=True, including_default_value_fields=True)
                for b in resp.benches]

    def import_runs(self, dataset, runs, model="taghizadeh2009", description=""):
        """Stores measured runs from arrays as batch 'import:<dataset>' (ImportRuns, operator role). Each run is a
        dict: id, supply_V, sample_period_s, gate (0/1), i_A, and optionally supply_pressure_Pa, t_start_s,
        split ('fit'|'holdout'|''), x_m, v_coil_V. The server validates the whole request (errors name the field,
        runs[3].gate[17]: must be 0 or 1) before storing anything."""
        req = api_pb2.ImportRunsRequest(dataset=dataset, model=model, description=description)
        for k, r in enumerate(runs):
            item = req.runs.add()
            for key, value in r.items():
                if key in ("gate",):
                    item.gate.extend(int(v) for v in np.asarray(value).ravel())
                elif key in ("i_A", "x_m", "v_coil_V"):
                    getattr(item, key).extend(float(v) for v in np.asarray(value, dtype=float).ravel())
                elif key in ("id", "split"):
                    setattr(item, key, str(value))
                elif key in ("supply_V", "supply_pressure_Pa", "t_start_s", "sample_period_s"):
                    setattr(item, key, float(value))
                else:
                    raise InvalidArgument("runs[%d].%s: unknown field (known: id, supply_V, supply_pressure_Pa, "
                                          "t_start_s, split, sample_period_s, gate, i_A, x_m, v_coil_V)" % (k, key))
        resp = self._call(self._api.ImportRuns, req, context="import " + dataset, timeout_s=300.0)
        return self.get_batch(resp.batch_id)

    # -- through benchctl: the dataset reader and the diagnosis are C++ (gap/), one implementation ----------

    def _benchctl(self, args, what):
        self._api  # follows a restarted private server, so self.server is current
        cmd = [find_tool("benchctl")] + args + ["--server", self.server]
        env = dict(os.environ, VALVEBENCH_TOKEN=self.token)
        if self.tls_ca:
            cmd += ["--tls-ca", self.tls_ca]
        proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
        if proc.returncode != 0:
            msg = proc.stderr.strip().replace("benchctl: ", "", 1) or ("benchctl exited %d" % proc.returncode)
            cls = InvalidArgument if proc.returncode == 2 else Error
            raise cls("%s: %s" % (what, msg))
        return proc.stdout

    def export(self, run_id, hdf5=None, mat=None, csv=None):
        """Writes a stored run as HDF5 and/or MATLAB .mat (and/or CSV) through benchctl export: channels with
        units, spec, conditions and metrics (docs/python.md "HDF5 and MATLAB files"). Returns the paths written."""
        args, paths = [], []
        for flag, path in (("--hdf5", hdf5), ("--mat", mat), ("--trace-csv", csv)):
            if path is not None:
                args += [flag, os.fspath(path)]
                paths.append(os.fspath(path))
        if not args:
            raise InvalidArgument("export: give hdf5=, mat= or csv=")
        self._benchctl(["export", str(int(run_id))] + args, "export run %d" % run_id)
        return paths

    def import_dataset(self, directory):
        """Stores a valve-runs/1 dataset (manifest.json + CSV files) as batch 'import:<name>' through benchctl
        import (the same reader as benchctl diagnose); returns the Batch."""
        out = self._benchctl(["import", os.fspath(directory), "--json"], "import " + os.fspath(directory))
        return self.get_batch(json.loads(out)["batch_id"])

    def diagnose(self, run_ids=None, batch=None, dataset=None, model=None):
        """The sim-to-real gap diagnosis (docs/gap.md) of stored runs (run_ids or a Batch) or of a dataset
        directory, as a valvebench.Diagnosis (the JSON of benchctl diagnose --json)."""
        if batch is not None:
            run_ids = batch.run_ids
        if (run_ids is None) == (dataset is None):
            raise InvalidArgument("diagnose: give run_ids (or batch) or dataset, not both and not neither")
        extra = ["--model", model] if model else []
        if dataset is not None:
            cmd = [find_tool("benchctl"), "diagnose", os.fspath(dataset), "--json"] + extra
            proc = subprocess.run(cmd, capture_output=True, text=True)
            if proc.returncode != 0:
                raise (InvalidArgument if proc.returncode == 2 else Error)(
                    proc.stderr.strip().replace("benchctl: ", "", 1))
            return Diagnosis(json.loads(proc.stdout))
        # Stored runs: the service's DiagnoseRuns (the diagnosis benchctl diagnose --runs and the web page get).
        req = api_pb2.DiagnoseRunsRequest(run_ids=[int(r) for r in run_ids])
        if model and os.path.isfile(os.fspath(model)):
            with open(os.fspath(model)) as f:
                try:
                    json_format.Parse(f.read(), req.model_spec)
                except json_format.ParseError as e:
                    raise InvalidArgument("model: %s: %s" % (os.fspath(model), e)) from None
        elif model:
            req.model = model
        resp = self._call(self._api.DiagnoseRuns, req, "diagnose", timeout_s=max(self.timeout_s or 0, 3600.0))
        return Diagnosis(json.loads(resp.report_json), report=resp.report,
                         improved_model_json=resp.improved_model_json)


class Diagnosis:
    """benchctl diagnose's result: ``data`` is the JSON (docs/gap.md); verdict, gap, ranking as a DataFrame.
    Of stored runs (the server's DiagnoseRuns) also ``report`` (the text benchctl prints) and
    ``improved_model_json`` (the model with the effect added, "" when none was attributed)."""

    def __init__(self, data, report="", improved_model_json=""):
        self.data = data
        self.report = report
        self.improved_model_json = improved_model_json
        self.verdict = data.get("verdict", "")
        self.verdict_reason = data.get("verdict_reason", "")
        self.gap = data.get("gap", {})

    def __getitem__(self, key):
        return self.data[key]

    def ranking(self):
        """The candidate effects ranked on holdout runs, best first: one row each (index: effect), columns
        fit_rmse_A, holdout_rmse_before_A, holdout_rmse_after_A, closed, signature_match, score, evaluations,
        and params / uncertainty (dicts of the fitted values, SI units)."""
        pd = _pandas()
        df = pd.DataFrame.from_records(self.data.get("ranking", []))
        return df.set_index("effect") if "effect" in df.columns else df

    def overlay(self, run=None):
        """Measured vs nominal vs fitted current of one run (default: the first overlay, a holdout run):
        DataFrame indexed by t_s with columns measured_A, nominal_A, fitted_A; attrs run and split."""
        pd = _pandas()
        overlays = self.data.get("overlays", [])
        chosen = [o for o in overlays if run is None or o["run"] == run]
        if not chosen:
            raise KeyError("diagnosis: no overlay for run '%s' (has: %s)" % (run, ", ".join(o["run"] for o in overlays)))
        o = chosen[0]
        df = pd.DataFrame({k: o[k] for k in ("measured_A", "nominal_A", "fitted_A") if k in o},
                          index=pd.Index(o["t_s"], name="t_s"))
        df.attrs.update(run=o["run"], split=o.get("split", ""), units={c: "A" for c in df.columns})
        return df

    def __repr__(self):
        return "Diagnosis(verdict=%r)" % self.verdict
