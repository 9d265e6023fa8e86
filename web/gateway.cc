// The gateway's API routes (web/routes.h, the list in web/gateway.h): each reads its HTTP request, calls the
// service through client::Client as the request's caller (client/: the views benchctl shares: the trace as CSV,
// a run's export file, a report's runs) and encodes the answer. The door's checks and the sessions are in
// web/door_routes.cc, the checks that need no route in web/checks.cc, the servers in web/server.cc.
#include "web/gateway.h"

#include <fmt/format.h>
#include <httplib.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <memory>
#include <optional>
#include <regex>
#include <set>
#include <string>
#include <vector>

#include <unistd.h>

#include "client/report_runs.h"
#include "client/run_file.h"
#include "client/run_key_json.h"
#include "client/trace_csv.h"
#include "client/trace_stream.h"
#include "common/trace_columns.h"
#include "experiment/compare.h"
#include "experiment/spec.h"
#include "export/run_file.h"
#include "gap/dataset.h"
#include "gap/import_request.h"
#include "model/params.h"
#include "report/report.h"
#include "web/door.h"
#include "web/http.h"
#include "web/routes.h"

namespace vb::web {

namespace v1 = valvebench::v1;

namespace {

// "runs=1,2,3" into `ids`; false (the answer sent) when it is not a list of run ids.
bool RunIdsParam(const httplib::Request& req, httplib::Response& res,
                        google::protobuf::RepeatedField<std::int64_t>* ids) {
  if (!req.has_param("runs")) return true;
  const std::string list = req.get_param_value("runs");
  size_t pos = 0;
  while (pos <= list.size()) {
    const size_t end = std::min(list.find(',', pos), list.size());
    const std::string item = list.substr(pos, end - pos);
    if (item.empty() || item.size() > 15 || item.find_first_not_of("0123456789") != std::string::npos) {
      BadRequest(res, "runs: must be run ids separated by commas, got '" + list + "'");
      return false;
    }
    ids->Add(std::stoll(item));
    pos = end + 1;
  }
  return true;
}

// The unit of every fitted parameter a diagnosis names, from the model's own tables (model::ParamUnit: a plant
// parameter, an effect's, a fit's "X_excess"). Unknown ones are left out.
Json DiagnosisParamUnits(const Json& d) {
  Json units = Json::object();
  auto add = [&](const Json& params) {
    if (!params.is_object()) return;
    for (const auto& [name, value] : params.items()) {
      (void)value;
      if (const std::string unit = model::ParamUnit(name); !unit.empty()) units[name] = unit;
    }
  };
  if (!d.is_object()) return units;
  for (const char* list : {"ranking", "detection_limits"})
    if (d.contains(list) && d[list].is_array())
      for (const auto& row : d[list])
        if (row.contains("params")) add(row["params"]);
  if (d.contains("parametric") && d["parametric"].contains("params")) add(d["parametric"]["params"]);
  return units;
}
// How the CLI's table shows each column (experiment::MetricColumnDisplay: one formatter for the CLI, the
// report and this page): {columns: {metric: {label, unit, header, scale, decimals, spread_decimals}},
// default_columns, sweep_axes: [{field, ...display}], keys: [RunKey per row], laws: {controller: name}}.
Json DisplayJson(const experiment::ColumnDisplay& d) {
  return Json{{"label", d.label}, {"unit", d.unit}, {"header", d.header}, {"scale", d.scale},
              {"decimals", d.decimals}, {"spread_decimals", d.spread_decimals}};
}
Json CompareDisplay(const v1::CompareRunsResponse& out) {
  // The rows' identity is the server's RunKey (CompareRow.key), never read back from the name.
  const experiment::Comparison c = experiment::ComparisonFromProto(out);
  Json keys = Json::array(), laws = Json::object();
  std::vector<std::string> axes;
  std::map<std::string, std::vector<double>> axis_values;
  for (const auto& row : c.rows) {
    laws[row.controller] = experiment::LawName(row.controller);
    Json sweep = Json::array();
    for (const auto& sc : row.key.sweep) {
      sweep.push_back({{"field", sc.field}, {"value", sc.value}});
      if (std::find(axes.begin(), axes.end(), sc.field) == axes.end()) axes.push_back(sc.field);
    }
    keys.push_back(client::RunKeyJson(row.key));
  }
  for (size_t i = 0; i < keys.size(); ++i)
    for (const auto& a : axes) {
      double v = NAN;
      for (const auto& sc : keys[i]["sweep"]) if (sc["field"] == a) v = sc["value"].get<double>();
      axis_values[a].push_back(v);
    }
  Json cols = Json::object();
  std::vector<std::string> all = c.columns;
  all.push_back(c.rank_metric);
  all.push_back(c.effort_metric);
  for (const auto& col : all) cols[col] = DisplayJson(experiment::MetricColumnDisplay(c, col));
  Json sweep_axes = Json::array();
  for (const auto& a : axes) {
    Json d = DisplayJson(experiment::SweepColumnDisplay(a, axis_values[a]));
    d["field"] = a;
    sweep_axes.push_back(d);
  }
  return Json{{"columns", cols}, {"default_columns", experiment::DefaultMetricColumns(c)},
              {"sweep_axes", sweep_axes}, {"keys", keys}, {"laws", laws}};
}


}  // namespace

client::Client Routes::As(const httplib::Request& req, double deadline_s, grpc::Status* rpc) const {
  // The header was checked by the door (Routes::Admit: visible ASCII only, what gRPC metadata may carry); it is
  // checked again here so that no other path can forward it unchecked. A session cookie was turned into the
  // header by Admit, on the routes it may authorise.
  std::string authorization;
  if (req.has_header("Authorization")) {
    std::string problem;
    if (const std::string token = BearerTokenOf(req.get_header_value("Authorization"), &problem); !token.empty())
      authorization = "Bearer " + token;
  }
  return client_.With({authorization, deadline_s, rpc});
}

void Routes::Benches(const httplib::Request& req, httplib::Response& res) {
  grpc::Status rpc;
  auto out = As(req, 10.0, &rpc).Benches();
  if (!out.ok()) return SendClientError(res, rpc, out.status());
  res.set_content(ToJson(*out), kJson);
}

// Running and queued runs with their place in the queue and their ETA: the service's GetQueue (the view
// `benchctl queue` shows too), in the JSON shape the page reads.
void Routes::Queue(const httplib::Request& req, httplib::Response& res) {
  grpc::Status rpc;
  auto got = As(req, 10.0, &rpc).GetQueue();
  if (!got.ok()) return SendClientError(res, rpc, got.status());
  const v1::GetQueueResponse& q = *got;
  std::string out = R"({"now_unix_s":)" + fmt::format("{:.3f}", q.at_unix_s()) + R"(,"live_benches":)" +
                    std::to_string(q.live_benches()) + R"(,"running":[)";
  for (int k = 0; k < q.running_size(); ++k) {
    const auto& x = q.running(k);
    // Appended piece by piece: GCC 12 -O3 reports a false -Wrestrict on a `"," + std::string` chain.
    if (k) out += ',';
    out.append(R"({"run":)").append(ToJson(x.run())).append(R"(,"eta_s":)");
    AppendNumber(&out, x.eta_s() < 0 ? NAN : x.eta_s());
    out += "}";
  }
  out += R"(],"queued":[)";
  for (int k = 0; k < q.queued_size(); ++k) {
    const auto& x = q.queued(k);
    if (k) out += ',';
    out += fmt::format(R"({{"position":{},"run":{},"eta_s":)", x.position(), ToJson(x.run()));
    AppendNumber(&out, x.eta_s() < 0 ? NAN : x.eta_s());
    out += "}";
  }
  out += "]}";
  res.set_content(out, kJson);
}

void Routes::ListRuns(const httplib::Request& req, httplib::Response& res) {
  v1::ListRunsRequest r;
  if (req.has_param("status")) {
    v1::RunStatus s;
    if (!v1::RunStatus_Parse(req.get_param_value("status"), &s))
      return BadRequest(res, "status: unknown run status '" + req.get_param_value("status") +
                                 "' (QUEUED, RUNNING, DONE, FAILED, CANCELLED, INTERRUPTED)");
    r.set_status(s);
  }
  long long batch = 0, page_size = 0;
  if (!IntParam(req, res, "batch_id", &batch) || !IntParam(req, res, "page_size", &page_size)) return;
  if (page_size < 0 || page_size > 1000) return BadRequest(res, "page_size: must be 0..1000");
  r.set_batch_id(batch);
  r.set_page_size(static_cast<int>(page_size));
  r.set_tag(req.get_param_value("tag"));
  r.set_bench(req.get_param_value("bench"));
  r.set_controller(req.get_param_value("controller"));
  r.set_page_token(req.get_param_value("page_token"));
  // The contract of api.proto's ListRunsRequest (AIP-132 order_by, a name filter): the service validates them
  // and names the field it refuses; the gateway only carries them.
  r.set_submitter(req.get_param_value("submitter"));
  r.set_name(req.get_param_value("name"));
  r.set_order_by(req.get_param_value("order_by"));
  double after_s = 0, before_s = 0;
  if (!NumberParam(req, res, "submitted_after_unix_s", &after_s) ||
      !NumberParam(req, res, "submitted_before_unix_s", &before_s))
    return;
  r.set_submitted_after_unix_s(after_s);
  r.set_submitted_before_unix_s(before_s);
  grpc::Status rpc;
  auto listed = As(req, 20.0, &rpc).ListRuns(r);
  if (!listed.ok()) return SendClientError(res, rpc, listed.status());
  const v1::ListRunsResponse& out = *listed;
  // Each law's headline metrics as its comparison shows them (experiment::RankMetricOf/EffortMetricOf: the
  // Compare page's effort axis, not a second choice made here): {controller: {rank, effort}}.
  Json headline = Json::object();
  for (const auto& run : out.runs()) {
    if (headline.contains(run.controller())) continue;
    auto view = [](const experiment::HeadlineMetric& m) {
      return Json{{"metric", m.metric}, {"label", m.label}, {"unit", m.unit}};
    };
    headline[run.controller()] = {{"rank", view(experiment::RankMetricOf(run.controller()))},
                                  {"effort", view(experiment::EffortMetricOf(run.controller()))}};
  }
  std::string body = ToJson(out);
  body.pop_back();  // the object's closing brace: the headline map goes beside the runs
  body += std::string(body.size() > 1 ? "," : "") + R"("headline":)" + Dump(headline) + "}";
  res.set_content(body, kJson);
}

// The body's spec goes through experiment::ParseSpecJson, the parser `benchctl run` uses, so a misspelt field
// gets the same "unknown field; did you mean" error; the service then validates it as for any gRPC caller.
void Routes::Submit(const httplib::Request& req, httplib::Response& res) {
  Json body;
  if (!BodyJson(req, res, &body)) return;
  for (const auto& [key, value] : body.items())
    if (key != "spec" && key != "batch_name")
      return BadRequest(res, key + ": unknown field (the body is {\"spec\": {...}, \"batch_name\": \"...\"})");
  if (!body.contains("spec") || !body["spec"].is_object()) return BadRequest(res, "spec: must be a JSON object");
  auto spec = experiment::ParseSpecJson(Dump(body["spec"]));
  if (!spec.ok()) return BadRequest(res, spec.status().message());
  std::string batch_name;
  if (body.contains("batch_name")) {
    if (!body["batch_name"].is_string()) return BadRequest(res, "batch_name: must be a string");
    batch_name = body["batch_name"].get<std::string>();
  }
  SubmitAndReply(req, res, *spec, batch_name);
}

void Routes::SubmitAndReply(const httplib::Request& req, httplib::Response& res, const v1::ExperimentSpec& spec,
                            const std::string& batch_name) {
  grpc::Status rpc;
  auto out = As(req, 30.0, &rpc).Submit(spec, batch_name);
  if (!out.ok()) return SendClientError(res, rpc, out.status());
  res.status = 201;
  res.set_content(ToJson(*out), kJson);
}

bool Routes::FetchRun(const httplib::Request& req, httplib::Response& res, std::int64_t id, v1::Run* run) {
  grpc::Status rpc;
  auto got = As(req, 10.0, &rpc).GetRun(id);
  if (!got.ok()) {
    SendClientError(res, rpc, got.status());
    return false;
  }
  *run = std::move(*got);
  return true;
}

void Routes::GetRun(const httplib::Request& req, httplib::Response& res) {
  v1::Run run;
  if (!FetchRun(req, res, PathId(req), &run)) return;
  Json units = Json::object();
  std::vector<std::string> names;
  for (const auto& [name, value] : run.metrics()) names.push_back(name);
  std::sort(names.begin(), names.end());
  for (const auto& name : names) units[name] = exportfile::MetricUnit(name, run.controller());
  Json channel_units = Json::object();
  for (const char* ch : {"gate", "v_coil_V", "i_A", "x_m", "v_mps", "ref", "u"})
    channel_units[ch] = exportfile::ChannelUnit(ch, run.controller());
  res.set_content(R"({"run":)" + ToJson(run) + R"(,"metric_units":)" + Dump(units) + R"(,"channel_units":)" +
                      Dump(channel_units) + "}",
                  kJson);
}

void Routes::Cancel(const httplib::Request& req, httplib::Response& res) {
  Json body;
  if (!BodyJson(req, res, &body)) return;
  std::string reason;
  if (body.contains("reason")) {
    if (!body["reason"].is_string()) return BadRequest(res, "reason: must be a string");
    reason = body["reason"].get<std::string>();
  }
  grpc::Status rpc;
  auto out = As(req, 30.0, &rpc).Cancel(PathId(req), reason);
  if (!out.ok()) return SendClientError(res, rpc, out.status());
  res.set_content(ToJson(*out), kJson);
}

// Re-run: the run's exact single-run spec (stored verbatim with it) submitted again as a new batch.
void Routes::Rerun(const httplib::Request& req, httplib::Response& res) {
  v1::Run run;
  const std::int64_t id = PathId(req);
  if (!FetchRun(req, res, id, &run)) return;
  // An imported run is a measurement (benchctl import): it has no spec a bench could run again.
  if (std::find(run.tags().begin(), run.tags().end(), "imported") != run.tags().end())
    return SendError(res, grpc::Status(grpc::StatusCode::FAILED_PRECONDITION,
                                       fmt::format("run {} is an imported measurement (benchctl import), not a bench run: "
                                                   "there is no spec to run again", id)));
  SubmitAndReply(req, res, run.spec(), fmt::format("rerun of run {}", id));
}

void Routes::TraceRows(const httplib::Request& req, httplib::Response& res) {
  double t_from = -INFINITY, t_to = INFINITY, max_points = 4000;
  if (!NumberParam(req, res, "t_from_s", &t_from) || !NumberParam(req, res, "t_to_s", &t_to) ||
      !NumberParam(req, res, "max_points", &max_points))
    return;
  if (max_points < 10 || max_points > 200000) return BadRequest(res, "max_points: must be 10..200000");
  if (std::isfinite(t_from) && std::isfinite(t_to) && t_to < t_from)
    return BadRequest(res, "t_to_s: must not be before t_from_s");
  // GetTrace windows and min/max-decimates on the server (common/decimate.h: every channel's extremes of a
  // bucket survive); the client decodes.
  v1::GetTraceRequest r;
  r.set_run_id(PathId(req));
  r.set_max_points(static_cast<std::int32_t>(max_points));
  // An open start: before any trace; an open end: to_s <= from_s (api.proto).
  r.set_from_s(std::isfinite(t_from) ? t_from : -1e300);
  r.set_to_s(std::isfinite(t_to) ? t_to : r.from_s());
  grpc::Status rpc;
  auto trace = As(req, 120.0, &rpc).GetTrace(r);
  if (!trace.ok()) return SendClientError(res, rpc, trace.status());
  const TraceColumns& t = *trace;
  // The rows [t_s, ch0, ch1, ...]: t_s is the rows' first column, not a channel.
  std::vector<std::string> channels;
  std::vector<const std::vector<double>*> cols;
  for (const auto& name : t.channels)
    if (name != "t_s") {
      channels.push_back(name);
      cols.push_back(t.Find(name));
    }
  std::string out = Dump(Json{{"channels", channels}, {"t0_s", t.t0_s}, {"sample_period_s", t.sample_period_s},
                              {"total_samples", t.total_samples}, {"decimated", t.decimated}});
  out.pop_back();
  out += R"(,"rows":[)";
  const std::size_t n = t.samples();
  out.reserve(out.size() + n * (cols.size() + 1) * 12);
  for (std::size_t k = 0; k < n; ++k) {
    out += k == 0 ? "[" : ",[";
    AppendNumber(&out, t.TimeAt(k));
    for (const auto* col : cols) {
      out += ',';
      AppendNumber(&out, (*col)[k]);
    }
    out += ']';
  }
  out += "]}";
  res.set_content(out, kJson);
}

// The whole trace as CSV, streamed: GetTrace's chunks are read one at a time as the client takes the rows, so
// memory stays at a chunk or two whatever the trace's size (docs/web.md "Limits"). The first chunk is read
// before answering, so a refusal (token, role, no such run) is still a JSON error with its status; an error
// later ends the download without its final chunk, which the browser reports as a failed download. The rows are
// client/trace_csv.h's, as benchctl export --csv writes them.
void Routes::TraceCsv(const httplib::Request& req, httplib::Response& res) {
  const std::int64_t id = PathId(req);
  v1::GetTraceRequest r;
  r.set_run_id(id);
  // The stream's calls keep their status in *rpc after this handler has returned: it lives as long as the stream.
  auto rpc = std::make_shared<grpc::Status>();
  auto opened = As(req, 3600.0, rpc.get()).OpenTrace(r);
  if (!opened.ok()) return SendClientError(res, *rpc, opened.status());
  std::shared_ptr<client::TraceStream> stream = std::move(*opened);
  res.set_header("Content-Disposition", fmt::format("attachment; filename=\"run{}.csv\"", id));
  res.set_header("Cache-Control", "no-store");
  auto header_sent = std::make_shared<bool>(false);
  res.set_chunked_content_provider(
      "text/csv; charset=utf-8",
      [rpc, stream, header_sent](size_t, httplib::DataSink& sink) {
        try {
          std::string out;
          if (!*header_sent) {
            out = client::TraceCsvHeader(stream->rows());
            *header_sent = true;
          } else if (!stream->Next()) {
            if (!stream->status().ok()) return false;  // cut short: no final chunk
            sink.done();
            return true;
          }
          client::AppendTraceCsvRows(stream->rows(), stream->first_row(), &out);
          stream->DropRows();  // memory: one chunk, whatever the trace's length
          if (!sink.write(out.data(), out.size())) {
            stream->Abandon();
            return false;
          }
          return true;
        } catch (...) {
          stream->Abandon();
          return false;
        }
      },
      [](bool) {});
}


// WatchRun re-emitted as Server-Sent Events: "event: run" with each RunEvent (protobuf JSON), then
// "event: end" with the final status once the run has ended, or "event: error" with {code, message}. A stream
// lasts at most watch_window_s; the browser's EventSource then reconnects by itself (docs/web.md "SSE").
void Routes::Events(const httplib::Request& req, httplib::Response& res) {
  double rate_Hz = 200.0;
  if (!NumberParam(req, res, "rate_Hz", &rate_Hz)) return;
  if (rate_Hz < 0.0 || rate_Hz > 1000.0) return BadRequest(res, "rate_Hz: must be 0..1000");
  // An interactive run is cancelled when its submitter's watch goes away (docs/server.md); a page's stream ends
  // with every navigation and every watch window, so the page does not watch those: benchctl does.
  grpc::Status st;
  auto got = As(req, 10.0, &st).GetRun(PathId(req));
  const v1::Run run = got.ok() ? *got : v1::Run();
  if (!got.ok() || run.spec().interactive()) {
    if (!got.ok() && st.ok()) st = grpc::Status(grpc::StatusCode::INTERNAL, got.status().message());
    const std::string data =
        got.ok() ? Dump(Json{{"code", "FAILED_PRECONDITION"},
                       {"message", "run " + std::to_string(run.id()) +
                                       " is interactive: follow it with benchctl watch (a watch from this page "
                                       "would cancel it when the page goes away)"}})
                : Dump(Json{{"code", CodeName(st.error_code())}, {"message", st.error_message()}});
    res.set_header("Cache-Control", "no-cache");
    res.set_content("event: error\ndata: " + data + "\n\n", "text/event-stream");
    return;
  }
  std::string why;
  auto slot = TakeStream(SessionKey(req), &why);
  if (!slot) {
    SendErrorStatus(res, 429, "RESOURCE_EXHAUSTED", why);
    res.set_header("Retry-After", "5");
    if (DoorRequestState* door = CurrentDoorRequest()) door->close_after = true;  // its connection goes too
    res.set_header("Connection", "close");
    return;
  }
  // Capped per session and in all (below the workers): not against its address's share of the workers, so
  // one address's tabs can follow as many runs as their sessions may.
  if (DoorRequestState* door = CurrentDoorRequest(); door && door->release_share) door->release_share();
  struct Watch {
    std::optional<client::Client> client;  // this request's caller, its deadline the watch window
    grpc::Status rpc;
    std::int64_t run_id = 0;
    double rate_Hz = 0.0, window_s = 0.0;
    std::shared_ptr<void> slot;  // the live view's place, held until the stream is gone
  };
  auto w = std::make_shared<Watch>();
  w->slot = std::move(slot);
  w->client = As(req, options_.watch_window_s, &w->rpc);
  w->run_id = PathId(req);
  w->rate_Hz = rate_Hz;
  w->window_s = options_.watch_window_s;
  res.set_header("Cache-Control", "no-cache");
  res.set_header("X-Accel-Buffering", "no");
  res.set_chunked_content_provider(
      "text/event-stream",
      [w](size_t, httplib::DataSink& sink) {
        auto send = [&](const std::string& event, const std::string& data) {
          const std::string msg = "event: " + event + "\ndata: " + data + "\n\n";
          return sink.write(msg.data(), msg.size());
        };
        if (!send("open", "{}") || !sink.write("retry: 500\n\n", 12)) return false;
        std::string last_status;
        bool ended = false, gone = false;
        (void)w->client->Watch(w->run_id, w->window_s, w->rate_Hz, [&](const v1::RunEvent& ev) {
          last_status = v1::RunStatus_Name(ev.status());
          ended = ev.status() != v1::QUEUED && ev.status() != v1::RUNNING;
          gone = !send("run", ToJson(ev, /*with_zeros=*/true));  // the page went away: the watch is cancelled
          return !gone;
        });
        if (gone) return false;
        const grpc::Status& st = w->rpc;
        if (!st.ok() && st.error_code() != grpc::StatusCode::DEADLINE_EXCEEDED) {
          send("error", Dump(Json{{"code", CodeName(st.error_code())}, {"message", st.error_message()}}));
        } else if (ended) {
          send("end", Dump(Json{{"status", last_status}}));
        }
        sink.done();
        return true;
      },
      [w](bool) {});
}

// The gap diagnosis of stored runs: DiagnoseRuns, run by the server (seconds to a minute).
void Routes::Diagnose(const httplib::Request& req, httplib::Response& res) {
  v1::DiagnoseRunsRequest r;
  if (!RunIdsParam(req, res, r.mutable_run_ids())) return;
  if (req.has_param("model")) r.set_model(req.get_param_value("model"));
  grpc::Status rpc;
  auto got = As(req, 300.0, &rpc).DiagnoseRuns(r);
  if (!got.ok()) return SendClientError(res, rpc, got.status());
  const v1::DiagnoseRunsResponse& out = *got;
  Json j = {{"report", out.report()}};
  j["diagnosis"] = Json::parse(out.report_json(), nullptr, false);
  // The nominal model with the diagnosed effect(s), as `benchctl diagnose --model-out` writes it ("" = none).
  j["improved_model_json"] = out.improved_model_json();
  j["param_units"] = DiagnosisParamUnits(j["diagnosis"]);
  res.set_content(Dump(j), kJson);
}


// CompareRuns on the query's batch (?batch_id=) or runs (?runs=): false when an error was answered.
bool Routes::FetchComparison(const httplib::Request& req, httplib::Response& res, v1::CompareRunsResponse* out,
                     long long* batch) {
  v1::CompareRunsRequest r;
  if (!IntParam(req, res, "batch_id", batch)) return false;
  r.set_batch_id(*batch);
  if (!RunIdsParam(req, res, r.mutable_run_ids())) return false;
  grpc::Status rpc;
  auto got = As(req, 30.0, &rpc).Compare(r.batch_id(), {r.run_ids().begin(), r.run_ids().end()});
  if (!got.ok()) {
    SendClientError(res, rpc, got.status());
    return false;
  }
  *out = std::move(*got);
  return true;
}

void Routes::Compare(const httplib::Request& req, httplib::Response& res) {
  long long batch = 0;
  v1::CompareRunsResponse out;
  if (!FetchComparison(req, res, &out, &batch)) return;
  // The unit of each column; rows of different laws may disagree (rmse is A for a current law, m for a
  // position law): then every unit seen, joined with " or ".
  Json units = Json::object();
  std::vector<std::string> cols(out.columns().begin(), out.columns().end());
  cols.push_back(out.rank_metric());
  cols.push_back(out.effort_metric());
  for (const auto& col : cols) {
    std::set<std::string> seen;
    for (const auto& row : out.rows()) seen.insert(exportfile::MetricUnit(col, row.controller()));
    std::string u;
    for (const auto& s : seen) u += (u.empty() ? "" : " or ") + s;
    units[col] = u;
  }
  // Zeros written (a metric at exactly 0 is a value, a missing one is absent from the row's map).
  res.set_content(R"({"comparison":)" + ToJson(out, /*with_zeros=*/true) + R"(,"units":)" + Dump(units) +
                      R"(,"display":)" + Dump(CompareDisplay(out)) + "}",
                  kJson);
}

// The SI prefixes the CLI's columns choose from (experiment::SiPrefixes), for the page's chart axes.
void Routes::Units(const httplib::Request&, httplib::Response& res) {
  Json p = Json::array();
  for (const auto& x : experiment::SiPrefixes()) p.push_back({{"symbol", x.symbol}, {"scale", x.scale}});
  res.set_content(Dump(Json{{"prefixes", p}}), kJson);
}

// The trace as HDF5 or MATLAB .mat, the files `benchctl export --hdf5/--mat` writes (client/run_file.h assembles
// both, export/run_file.h writes them). Both formats are written whole by their libraries, so the run's samples
// are held in memory while the file is written (to a temporary file, unlinked at once) and the file is then
// streamed from disk in 64 KiB pieces; a trace above kMaxFileTraceBytes is refused (413) with the CLI to use.
void Routes::TraceFile(const httplib::Request& req, httplib::Response& res) {
  constexpr std::size_t kMaxFileTraceBytes = std::size_t{256} << 20;
  const std::int64_t id = PathId(req);
  const std::string format = req.matches[2].str();
  v1::Run run;
  if (!FetchRun(req, res, id, &run)) return;
  // An HDF5 or MAT file is built whole in memory (up to kMaxFileTraceBytes of trace, and the file): at most
  // kMaxExportsPerSession per token and kMaxExports at once (issue 34: eight at once took +3.6 GB).
  std::string busy;
  const auto slot = TakeExport(SessionKey(req), &busy);
  if (!slot) {
    res.set_header("Retry-After", "5");
    return SendErrorStatus(res, 429, "RESOURCE_EXHAUSTED", busy);
  }
  grpc::Status rpc;
  client::Client caller = As(req, 600.0, &rpc);
  auto f = client::FetchRunFile(caller, run, kMaxFileTraceBytes);
  if (!f.ok() && rpc.ok() && f.status().code() == StatusCode::kResourceExhausted)
    return SendErrorStatus(res, 413, "RESOURCE_EXHAUSTED",
                           fmt::format("{}, too large for a {} file from the page; use benchctl export {} --{} FILE",
                                       f.status().message(), format, id, format == "h5" ? "hdf5" : "mat"));
  if (!f.ok()) return SendClientError(res, rpc, f.status());
  char path[] = "/tmp/valvebench-web-XXXXXX";
  const int fd = mkstemp(path);
  if (fd < 0) return SendError(res, grpc::StatusCode::UNAVAILABLE, "export: cannot create a temporary file");
  ::close(fd);
  const Status written = format == "h5" ? exportfile::WriteHdf5(*f, path) : exportfile::WriteMat(*f, path);
  std::FILE* file = written.ok() ? std::fopen(path, "rb") : nullptr;
  std::remove(path);  // the open file stays readable; nothing is left behind
  if (!written.ok()) return SendError(res, grpc::StatusCode::INTERNAL, written.message());
  if (file == nullptr) return SendError(res, grpc::StatusCode::UNAVAILABLE, "export: cannot read the written file");
  auto handle = std::shared_ptr<std::FILE>(file, &std::fclose);
  *f = {};  // the samples are in the file now
  res.set_header("Content-Disposition", fmt::format("attachment; filename=\"run{}.{}\"", id, format));
  res.set_chunked_content_provider(
      format == "h5" ? "application/x-hdf5" : "application/x-matlab-data",
      [handle](size_t, httplib::DataSink& sink) {
        char buf[64 * 1024];
        const size_t got = std::fread(buf, 1, sizeof buf, handle.get());
        if (got > 0 && !sink.write(buf, got)) return false;
        if (got < sizeof buf) {
          if (std::ferror(handle.get())) return false;
          sink.done();
        }
        return true;
      },
      [](bool) {});
}


// The comparison as the files `benchctl compare --csv/--json` prints (experiment::ComparisonCsv/Json): a
// missing metric is an empty CSV field and a JSON null (docs/cli.md "Missing values").
void Routes::CompareFile(const httplib::Request& req, httplib::Response& res) {
  const std::string format = req.matches[1].str();
  long long batch = 0;
  v1::CompareRunsResponse out;
  if (!FetchComparison(req, res, &out, &batch)) return;
  const experiment::Comparison c = experiment::ComparisonFromProto(out);
  const std::string name = batch != 0 ? fmt::format("batch{}-comparison", batch) : "comparison";
  res.set_header("Content-Disposition", fmt::format("attachment; filename=\"{}.{}\"", name, format));
  if (format == "csv")
    res.set_content(experiment::ComparisonCsv(c), "text/csv; charset=utf-8");
  else
    res.set_content(experiment::ComparisonJson(c), kJson);
}

// A batch's HTML report, the page `benchctl report --batch N --html FILE` writes: the runs gathered by the same
// view (client/report_runs.h) and rendered by the same code (report::BatchSections, RenderHtml). The traces are
// read whole (the report decimates them itself) up to kMaxReportTraceBytes in all; the runs beyond that are in
// the tables without their trace, and the page says how many.
void Routes::BatchReport(const httplib::Request& req, httplib::Response& res) {
  constexpr std::size_t kMaxReportTraceBytes = std::size_t{256} << 20;
  constexpr int kMaxReportTraces = 100;  // benchctl report's --max-traces default
  const std::int64_t batch = PathId(req);
  grpc::Status rpc;
  client::Client caller = As(req, 120.0, &rpc);
  auto got = client::FetchReportRuns(caller, batch, {}, {kMaxReportTraces, kMaxReportTraceBytes});
  if (!got.ok()) return SendClientError(res, rpc, got.status());
  std::string where = "web dashboard (" + req.get_header_value("Host") + ")";
  if (got->traces_left_out > 0)
    where += fmt::format("; traces of {} runs left out (size): benchctl report --batch {}", got->traces_left_out,
                         batch);
  const std::string html =
      report::RenderHtml(client::BatchReportTitle(batch, got->runs), report::BatchSections(where, batch, got->runs));
  // The report draws its charts with inline scripts (it is one self-contained file): the dashboard's CSP
  // would block them; this answer's CSP allows exactly those scripts, by their hashes.
  res.headers.erase("Content-Security-Policy");
  res.set_header("Content-Security-Policy", ReportCsp(html));
  res.set_header("Content-Disposition", fmt::format("inline; filename=\"batch{}-report.html\"", batch));
  res.set_content(html, "text/html; charset=utf-8");
}


// A measured dataset uploaded from the page: {"dataset": NAME, "files": {"manifest.json": TEXT, "a.csv": TEXT,
// ...}} (within the 8 MiB body limit). The files are read in memory by gap::LoadDatasetFromFiles, the reader of
// `benchctl import DIR` (gap::LoadDataset) without the directory, so a bad file gets the same error naming the
// file, the line and the field, and nothing is written to disk; the runs then go to the service's ImportRuns
// (operator role) as benchctl sends them (gap::FillImportRequest).
void Routes::Import(const httplib::Request& req, httplib::Response& res) {
  Json body;
  if (!BodyJson(req, res, &body)) return;
  if (!body.is_object()) return BadRequest(res, "body: must be a JSON object {\"dataset\", \"files\"}");
  for (const auto& [key, value] : body.items())
    if (key != "dataset" && key != "files")
      return BadRequest(res, key + ": unknown field (the body is {\"dataset\": \"...\", \"files\": {...}})");
  static const std::regex name_re(R"([A-Za-z0-9][A-Za-z0-9._-]{0,99})");
  if (!body.contains("dataset") || !body["dataset"].is_string())
    return BadRequest(res, "dataset: must be a string (the dataset's name)");
  const std::string dataset = body["dataset"].get<std::string>();
  if (!std::regex_match(dataset, name_re))
    return BadRequest(res, "dataset: '" + dataset + "' must be 1-100 characters of A-Z a-z 0-9 . _ - (not starting with . _ -)");
  if (!body.contains("files") || !body["files"].is_object() || body["files"].empty())
    return BadRequest(res, "files: must be an object of file name -> text (manifest.json and its CSV files)");
  if (body["files"].size() > 2000) return BadRequest(res, "files: more than 2000 files");
  for (const auto& [fname, text] : body["files"].items()) {
    if (!std::regex_match(fname, name_re))
      return BadRequest(res, "files['" + fname + "']: a file name of A-Z a-z 0-9 . _ - (no directories)");
    if (!text.is_string()) return BadRequest(res, "files['" + fname + "']: must be the file's text");
  }
  if (!body["files"].contains("manifest.json"))
    return BadRequest(res, "files: no manifest.json (pick the dataset's manifest.json and its files)");
  // Each data file's header row, in time linear in its length, before a byte is written (issue 34: the
  // dataset reader's duplicate check is a search per column, 150k columns took 45 s).
  for (const auto& [fname, text] : body["files"].items()) {
    if (fname.size() >= 5 && fname.compare(fname.size() - 5, 5, ".json") == 0) continue;
    const std::string why = CsvHeaderProblem(text.get_ref<const std::string&>());
    if (!why.empty()) return BadRequest(res, dataset + "/" + fname + ":1: " + why);
  }
  std::map<std::string, std::string> files;
  for (const auto& [fname, text] : body["files"].items()) files[fname] = text.get<std::string>();
  auto ds = gap::LoadDatasetFromFiles(dataset, files, model::PresetNames());
  if (!ds.ok()) return BadRequest(res, ds.status().message());
  v1::ImportRunsRequest r;
  if (auto st = gap::FillImportRequest(*ds, dataset, &r); !st.ok()) return BadRequest(res, st.message());
  grpc::Status rpc;
  auto out = As(req, 120.0, &rpc).ImportRuns(r);
  if (!out.ok()) return SendClientError(res, rpc, out.status());
  Json j = Json::parse(ToJson(*out));
  j["warnings"] = ds->warnings;
  res.status = 201;
  res.set_content(Dump(j), kJson);
}

void Routes::Nights(const httplib::Request& req, httplib::Response& res) {
  long long limit = 0;
  if (!IntParam(req, res, "limit", &limit)) return;
  if (limit < 0 || limit > 1000) return BadRequest(res, "limit: must be 0..1000");
  v1::ListNightsRequest r;
  r.set_limit(static_cast<int>(limit));
  grpc::Status rpc;
  auto out = As(req, 10.0, &rpc).ListNights(r.limit());
  if (!out.ok()) return SendClientError(res, rpc, out.status());
  Json j = Json::parse(ToJson(*out));
  if (options_.next_night_unix_s) {
    if (auto next = options_.next_night_unix_s(); next.ok()) j["next_night_unix_s"] = *next;
  }
  res.set_content(Dump(j), kJson);
}

// Each bench's tracked valve (GetBenchHealth, docs/track.md "On the server"): ?bench= one bench, else every
// bench with checks stored. The service checks the name (length, known bench).
void Routes::Health(const httplib::Request& req, httplib::Response& res) {
  v1::GetBenchHealthRequest r;
  r.set_bench(req.get_param_value("bench"));
  grpc::Status rpc;
  auto out = As(req, 30.0, &rpc).GetBenchHealth(r.bench());
  if (!out.ok()) return SendClientError(res, rpc, out.status());
  res.set_content(ToJson(*out), kJson);
}

}  // namespace vb::web
