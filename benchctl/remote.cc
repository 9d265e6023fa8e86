#include "benchctl/remote.h"

#include <google/protobuf/util/json_util.h>

#include <cmath>
#include <cstdio>
#include <iostream>
#include <memory>

#include "benchctl/backend.h"
#include "benchctl/cli_common.h"
#include "proto/api_convert.h"
#include "common/csv.h"
#include "experiment/compare.h"
#include "experiment/spec.h"

namespace vb::benchctl {

namespace v1 = valvebench::v1;

namespace {

std::string ToJson(const google::protobuf::Message& m) {
  std::string out;
  google::protobuf::util::JsonPrintOptions opts;
  opts.add_whitespace = true;
  opts.preserve_proto_field_names = true;
  (void)google::protobuf::util::MessageToJsonString(m, &out, opts);
  return out;
}

// The one status vocabulary (common/run_status.h) for whatever the server sends.
const char* StatusWord(v1::RunStatus s) {
  const auto status = api::FromProto(s);
  return status ? RunStatusName(*status) : "?";
}

bool Ended(v1::RunStatus s) {
  const auto status = api::FromProto(s);
  return status && vb::Ended(*status);
}

int ExitForRun(const v1::Run& r) { return r.status() == v1::DONE ? kExitOk : kExitRunFailed; }

void PrintRun(const v1::Run& r) {
  std::printf("run %lld [%s] %s: %s", static_cast<long long>(r.id()), r.controller().c_str(), r.name().c_str(),
              StatusWord(r.status()));
  if (!r.reason().empty()) std::printf(" (%s)", r.reason().c_str());
  std::printf("\n  batch %lld, bench %s, submitter %s, priority %d, progress %.0f%%\n",
              static_cast<long long>(r.batch_id()), r.bench().empty() ? "-" : r.bench().c_str(),
              r.submitter().c_str(), r.priority(), 100.0 * r.progress());
  for (const auto& [name, value] : r.metrics()) std::printf("  %-20s %.6g\n", name.c_str(), value);
}

// Progress bar on stderr until the run ends; returns the final status.
StatusOr<v1::Run> WaitFor(client::Client& c, std::int64_t run_id, bool bar) {
  v1::RunStatus last = v1::RUN_STATUS_UNSPECIFIED;
  auto st = c.Watch(run_id, 24 * 3600.0, -1.0, [&](const v1::RunEvent& ev) {
    last = ev.status();
    if (bar) {
      const int filled = static_cast<int>(std::lround(30.0 * ev.progress()));
      std::fprintf(stderr, "\rrun %lld [%-30s] %3.0f%% %-11s", static_cast<long long>(run_id),
                   std::string(static_cast<size_t>(filled), '#').c_str(), 100.0 * ev.progress(),
                   StatusWord(ev.status()));
      std::fflush(stderr);
    }
    return !Ended(ev.status());
  });
  if (bar) std::fprintf(stderr, "\n");
  if (!st.ok()) return st;
  (void)last;
  return c.GetRun(run_id);
}

}  // namespace

int RemoteRun(client::Client& c, const std::string& spec_path, bool wait, const Output& out) {
  auto spec = experiment::LoadSpecFile(spec_path);
  if (!spec.ok()) return Fail(spec.status());
  auto resp = c.Submit(*spec);
  if (!resp.ok()) return Fail(resp.status().WithContext(spec_path));
  if (!wait) {
    if (out.json) {
      std::cout << ToJson(*resp) << "\n";
    } else {
      std::printf("batch %lld:", static_cast<long long>(resp->batch_id()));
      for (auto id : resp->run_ids()) std::printf(" %lld", static_cast<long long>(id));
      std::printf("\n");
    }
    return kExitOk;
  }
  int code = kExitOk;
  std::string all = "[";
  for (int k = 0; k < resp->run_ids_size(); ++k) {
    auto run = WaitFor(c, resp->run_ids(k), !out.json);
    if (!run.ok()) return Fail(run.status());
    if (ExitForRun(*run) != kExitOk) code = kExitRunFailed;
    if (out.json) {
      all += (k ? ",\n" : "") + ToJson(*run);
    } else {
      PrintRun(*run);
    }
  }
  if (out.json) std::cout << all << "]\n";
  if (!out.json && resp->run_ids_size() > 1) {
    auto cmp = RemoteComparison(c, resp->batch_id(), {});
    if (cmp.ok()) std::cout << "\n" << experiment::ComparisonTable(*cmp);
  }
  return code;
}

int RemoteQueue(client::Client& c, const std::string& status, std::int64_t batch, const std::string& tag, int limit,
                const Output& out) {
  v1::ListRunsRequest req;
  if (!status.empty()) {
    v1::RunStatus s;
    std::string upper = status;
    for (char& ch : upper) ch = static_cast<char>(std::toupper(static_cast<unsigned char>(ch)));
    if (!v1::RunStatus_Parse(upper, &s))
      return Fail(Status::InvalidArgument("--status: '" + status +
                                          "' is not one of queued, running, done, failed, cancelled, interrupted"));
    req.set_status(s);
  }
  req.set_batch_id(batch);
  req.set_tag(tag);
  req.set_page_size(limit);
  auto resp = c.ListRuns(req);
  if (!resp.ok()) return Fail(resp.status());
  if (out.json) {
    std::cout << ToJson(*resp) << "\n";
    return kExitOk;
  }
  if (out.csv) std::printf("id,batch,status,priority,progress,controller,submitter,name\n");
  for (const auto& r : resp->runs()) {
    if (out.csv) {
      std::printf("%lld,%lld,%s,%d,%.3f,%s,%s,%s\n", static_cast<long long>(r.id()),
                  static_cast<long long>(r.batch_id()), StatusWord(r.status()), r.priority(), r.progress(),
                  r.controller().c_str(), r.submitter().c_str(), CsvQuoted(r.name()).c_str());
    } else {
      std::printf("%6lld  batch %-5lld %-11s prio %-3d %4.0f%%  %-22s %-10s %s\n", static_cast<long long>(r.id()),
                  static_cast<long long>(r.batch_id()), StatusWord(r.status()), r.priority(), 100.0 * r.progress(),
                  r.controller().c_str(), r.submitter().c_str(), r.name().c_str());
    }
  }
  if (!resp->next_page_token().empty() && !out.csv)
    std::fprintf(stderr, "(more runs: raise --limit)\n");
  return kExitOk;
}

int RemoteShow(client::Client& c, std::int64_t run_id, const Output& out) {
  auto r = c.GetRun(run_id);
  if (!r.ok()) return Fail(r.status());
  if (out.json) {
    std::cout << ToJson(*r) << "\n";
  } else {
    PrintRun(*r);
    for (const auto& h : r->history())
      std::printf("  history: %-11s at %.3f %s\n", StatusWord(h.status()), h.at_unix_s(), h.reason().c_str());
  }
  return kExitOk;
}

int RemoteWatch(client::Client& c, std::int64_t run_id, const Output& out) {
  if (out.json) {
    auto st = c.Watch(run_id, 24 * 3600.0, 0.0, [&](const v1::RunEvent& ev) {
      std::string line;
      google::protobuf::util::JsonPrintOptions opts;
      opts.preserve_proto_field_names = true;
      (void)google::protobuf::util::MessageToJsonString(ev, &line, opts);
      std::cout << line << "\n" << std::flush;
      return !Ended(ev.status());
    });
    if (!st.ok()) return Fail(st);
    auto r = c.GetRun(run_id);
    return r.ok() ? ExitForRun(*r) : Fail(r.status());
  }
  auto r = WaitFor(c, run_id, true);
  if (!r.ok()) return Fail(r.status());
  PrintRun(*r);
  return ExitForRun(*r);
}

int RemoteCancel(client::Client& c, std::int64_t run_id, const std::string& reason, const Output& out) {
  auto r = c.Cancel(run_id, reason);
  if (!r.ok()) return Fail(r.status());
  if (out.json) {
    std::cout << ToJson(*r) << "\n";
  } else {
    PrintRun(*r);
  }
  return kExitOk;
}

int RemoteExport(client::Client& c, std::int64_t run_id, const std::string& csv_path) {
  auto t = c.GetTrace(run_id);
  if (!t.ok()) return Fail(t.status());
  std::unique_ptr<FILE, int (*)(FILE*)> f(csv_path == "-" ? stdout : std::fopen(csv_path.c_str(), "w"),
                                          csv_path == "-" ? +[](FILE*) { return 0; } : &std::fclose);
  if (!f) return Fail(Status::Unavailable(csv_path + ": cannot open for writing"));
  for (size_t ch = 0; ch < t->channels.size(); ++ch) std::fprintf(f.get(), "%s%s", ch ? "," : "", t->channels[ch].c_str());
  std::fputc('\n', f.get());
  std::vector<const std::vector<double>*> cols;
  for (const auto& name : t->channels) cols.push_back(&t->columns.at(name));
  for (size_t k = 0; k < t->samples(); ++k) {
    for (size_t ch = 0; ch < cols.size(); ++ch) std::fprintf(f.get(), "%s%.10g", ch ? "," : "", (*cols[ch])[k]);
    std::fputc('\n', f.get());
  }
  if (std::ferror(f.get())) return Fail(Status::DataLoss(csv_path + ": write failed"));
  return kExitOk;
}

}  // namespace vb::benchctl
