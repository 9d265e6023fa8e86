#include "client/report_runs.h"

#include <fmt/format.h>

#include <algorithm>
#include <map>
#include <utility>

#include "client/trace_stream.h"
#include "common/run_status.h"
#include "experiment/spec.h"
#include "proto/api_convert.h"

namespace vb::client {

namespace v1 = valvebench::v1;

namespace {

constexpr std::size_t kMaxListed = 20000;  // a batch's runs, at most (pages of 1000)

// The run's trace into `info` within what is left of the limits; `bytes` counts across runs.
Status AddTrace(Client& client, const v1::Run& run, const ReportLimits& limits, std::size_t* bytes, bool* left_out,
                report::RunInfo* info) {
  v1::GetTraceRequest r;
  r.set_run_id(run.id());
  auto stream = client.OpenTrace(r, 120.0);
  if (!stream.ok()) {
    if (stream.status().code() == StatusCode::kNotFound) return Status::Ok();  // ended without a trace
    return stream.status();
  }
  TraceStream& s = **stream;
  const std::size_t before = *bytes;
  for (;;) {
    if (limits.max_trace_bytes > 0 && before + s.bytes() > limits.max_trace_bytes) {
      s.Abandon();
      *bytes = before + s.bytes();
      *left_out = true;
      return Status::Ok();
    }
    if (!s.Next()) break;
  }
  *bytes = before + s.bytes();
  if (s.status().code() == StatusCode::kDataLoss)
    return Status::DataLoss(fmt::format("run {}: its trace's chunks do not decode", run.id()));
  if (s.status().code() == StatusCode::kNotFound) return Status::Ok();
  if (!s.status().ok()) return s.status();
  TraceColumns cols = s.TakeAll();
  if (cols.columns.empty()) return Status::Ok();
  info->trace.label = fmt::format("run {}: {}", run.id(), run.name());
  info->trace.t0_s = cols.t0_s;
  info->trace.sample_period_s = cols.sample_period_s;
  info->trace.channels = std::move(cols.columns);
  return Status::Ok();
}

}  // namespace

report::RunInfo RunInfoOf(const v1::Run& run) {
  return report::RunInfo{run.id(),
                         api::FromProto(run.key()),
                         run.controller(),
                         api::FromProto(run.status()).value_or(RunStatus::kQueued),
                         std::map<std::string, double>(run.metrics().begin(), run.metrics().end()),
                         run.has_spec() ? experiment::SpecToJson(run.spec(), /*pretty=*/false) : std::string(),
                         run.submitted_unix_s(),
                         run.started_unix_s(),
                         run.finished_unix_s(),
                         {}};
}

StatusOr<ReportRuns> FetchReportRuns(Client& client, std::int64_t batch, const std::vector<std::int64_t>& run_ids,
                                     const ReportLimits& limits) {
  std::vector<std::int64_t> ids = run_ids;
  if (batch != 0) {
    ids.clear();
    v1::ListRunsRequest lr;
    lr.set_batch_id(batch);
    lr.set_page_size(1000);
    lr.set_order_by("id");
    do {
      auto page = client.ListRuns(lr);
      if (!page.ok()) return page.status();
      for (const auto& r : page->runs()) ids.push_back(r.id());
      lr.set_page_token(page->next_page_token());
    } while (!lr.page_token().empty() && ids.size() < kMaxListed);
    if (ids.empty()) return Status::NotFound(fmt::format("batch {}: no runs", batch));
    std::sort(ids.begin(), ids.end());
  }
  ReportRuns out;
  std::size_t bytes = 0;
  int traced = 0;
  for (const std::int64_t id : ids) {
    auto run = client.GetRun(id);  // ListRuns leaves the spec out; the report shows it
    if (!run.ok()) return run.status();
    report::RunInfo info = RunInfoOf(*run);
    const bool ended = run->status() != v1::QUEUED && run->status() != v1::RUNNING;  // no trace before
    const bool room = traced < limits.max_traces && (limits.max_trace_bytes == 0 || bytes < limits.max_trace_bytes);
    if (ended && room) {
      bool left_out = false;
      if (Status st = AddTrace(client, *run, limits, &bytes, &left_out, &info); !st.ok()) return st;
      if (left_out) ++out.traces_left_out;
      if (!info.trace.channels.empty()) ++traced;
    } else if (ended) {
      ++out.traces_left_out;
    }
    out.runs.push_back(std::move(info));
  }
  return out;
}

std::string BatchReportTitle(std::int64_t batch, const std::vector<report::RunInfo>& runs) {
  const std::string& name = runs.empty() ? std::string() : runs.front().key.name;
  return fmt::format("Batch {}: {}", batch, name.substr(0, name.find('/')));
}

}  // namespace vb::client
