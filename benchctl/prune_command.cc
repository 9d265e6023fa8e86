#include "benchctl/prune_command.h"

#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <iostream>
#include <sstream>

#include <nlohmann/json.hpp>

#include "benchctl/cli_common.h"
#include "client/client.h"
#include "service/local_service.h"
#include "proto/api_convert.h"
#include "valvebench/v1/api.pb.h"
#include "common/format.h"

namespace vb::benchctl {
namespace {

namespace v1 = valvebench::v1;
using Json = nlohmann::ordered_json;

std::string UtcTime(double unix_s) { return unix_s <= 0 ? "-" : FormatUtc(unix_s); }

std::string Bytes(std::int64_t b) {
  char buf[32];
  if (b >= 1'000'000'000) std::snprintf(buf, sizeof buf, "%.2f GB", b / 1e9);
  else if (b >= 1'000'000) std::snprintf(buf, sizeof buf, "%.1f MB", b / 1e6);
  else if (b >= 1'000) std::snprintf(buf, sizeof buf, "%.1f kB", b / 1e3);
  else std::snprintf(buf, sizeof buf, "%lld B", static_cast<long long>(b));
  return buf;
}

// PruneRuns (admin) through the one client (client/client.h) of a service: a server's, or the local service's
// over the local store (its own admin token): one path, the service's prune rules either way.
StatusOr<v1::PruneRunsResponse> Prune(client::Client& c, const std::string& where, double age_s,
                                      std::int32_t keep_last, bool dry_run) {
  v1::PruneRunsRequest req;
  req.set_older_than_s(age_s);
  req.set_keep_last(keep_last);
  req.set_dry_run(dry_run);
  auto resp = c.PruneRuns(req);
  if (!resp.ok()) return resp.status().WithContext(where);
  return resp;
}

StatusOr<v1::PruneRunsResponse> PruneLocal(const std::string& path, double age_s, std::int32_t keep_last, bool dry_run) {
  if (path.empty()) return Status::InvalidArgument("--no-store: prune needs the local store (--db FILE)");
  server::LocalServiceOptions o;
  o.store = path;
  o.execute = false;
  o.must_exist = true;  // pruning a store that is not there would create an empty one: say so instead
  auto local = server::LocalService::Start(o);
  if (!local.ok()) return local.status();
  client::ClientOptions co;
  co.address = (*local)->Where();
  co.token = (*local)->token();
  client::Client c((*local)->InProcessChannel(), co);
  return Prune(c, (*local)->Where(), age_s, keep_last, dry_run);
}

StatusOr<v1::PruneRunsResponse> PruneRemote(const SharedOptions& o, double age_s, std::int32_t keep_last, bool dry_run) {
  client::ClientOptions co;
  co.address = *o.server;
  co.token = *o.token;
  if (!o.tls_ca_file->empty()) {  // the client reads no files: the PEM's contents
    std::ifstream in(*o.tls_ca_file);
    if (!in) return Status::InvalidArgument("--tls-ca: cannot read " + *o.tls_ca_file);
    std::stringstream ss;
    ss << in.rdbuf();
    co.tls_ca_pem = ss.str();
  }
  client::Client c(co);
  return Prune(c, "server " + *o.server, age_s, keep_last, dry_run);
}

Json ToJson(const v1::PruneDecision& d) {
  return Json{{"run_id", d.run_id()},   {"batch_id", d.batch_id()},
              {"name", d.name()},       {"status", RunStatusName(api::FromProto(d.status()).value_or(RunStatus::kFailed))},
              {"finished_unix_s", d.finished_unix_s()}, {"why", d.why()}};
}

void Print(const v1::PruneRunsResponse& r, const std::string& where, bool json) {
  if (json) {
    Json j{{"where", where}, {"dry_run", r.dry_run()}, {"cutoff_unix_s", r.cutoff_unix_s()}};
    Json del = Json::array(), kept = Json::array();
    for (const auto& d : r.deleted()) del.push_back(ToJson(d));
    for (const auto& d : r.kept()) kept.push_back(ToJson(d));
    j["deleted"] = del;
    j["kept"] = kept;
    j["newer_kept"] = r.newer_kept();
    j["trace_bytes"] = r.trace_bytes();
    j["batches_deleted"] = r.batches_deleted();
    std::cout << j.dump(2) << "\n";
    return;
  }
  std::printf("prune %s%s: finished runs that ended before %s\n", where.c_str(), r.dry_run() ? " (dry run)" : "",
              UtcTime(r.cutoff_unix_s()).c_str());
  std::printf("%s %d run(s), %s of traces, %lld batch(es) left empty\n", r.dry_run() ? "would delete" : "deleted",
              r.deleted_size(), Bytes(r.trace_bytes()).c_str(), static_cast<long long>(r.batches_deleted()));
  auto line = [](const v1::PruneDecision& d) {
    std::printf("  run %-6lld batch %-5lld %-9s %-20s %s\n      %s\n", static_cast<long long>(d.run_id()),
                static_cast<long long>(d.batch_id()),
                RunStatusName(api::FromProto(d.status()).value_or(RunStatus::kFailed)),
                UtcTime(d.finished_unix_s()).c_str(), d.name().c_str(), d.why().c_str());
  };
  for (const auto& d : r.deleted()) line(d);
  std::printf("kept %d run(s) that are old or unfinished:\n", r.kept_size());
  for (const auto& d : r.kept()) line(d);
  std::printf("kept %lld newer finished run(s)\n", static_cast<long long>(r.newer_kept()));
}

}  // namespace

StatusOr<double> ParseAge(const std::string& text) {
  const auto bad = [&] {
    return Status::InvalidArgument("--older-than: '" + text +
                                   "' is not an age; give a number and a unit: 30d, 12h, 90m, 3600s, 2w");
  };
  if (text.size() < 2) return bad();
  const char unit = text.back();
  double scale = 0;
  switch (unit) {
    case 's': scale = 1; break;
    case 'm': scale = 60; break;
    case 'h': scale = 3600; break;
    case 'd': scale = 86400; break;
    case 'w': scale = 7 * 86400; break;
    default: return bad();
  }
  const std::string number = text.substr(0, text.size() - 1);
  std::size_t used = 0;
  double v = 0;
  try {
    v = std::stod(number, &used);
  } catch (const std::exception&) {
    return bad();
  }
  if (used != number.size() || !std::isfinite(v)) return bad();
  if (v <= 0) return Status::InvalidArgument("--older-than: must be > 0, got '" + text + "'");
  const double s = v * scale;
  if (s > 200.0 * 365.25 * 86400) return Status::InvalidArgument("--older-than: '" + text + "' reaches before 1970");
  return s;
}

PruneCli::PruneCli(CLI::App* app, SharedOptions shared) : shared_(shared) {
  cmd_ = app->add_subcommand("prune", "delete old finished runs and their traces (never baselines' or nights' runs, "
                                      "never queued or running runs)");
  cmd_->add_option("--older-than", older_than_, "age of the runs to delete: 30d, 12h, 90m, 3600s, 2w")->required();
  cmd_->add_option("--keep-last", keep_last_, "always keep the newest N finished runs (default 0)");
  cmd_->add_flag("--dry-run", dry_run_, "say what would be deleted and kept; delete nothing");
  cmd_->add_flag("--local", local_, "prune the local store (default when no server is given)");
  cmd_->add_option("--db", *shared_.store_path, "local store (default $VALVEBENCH_DB or ~/.local/share/valvebench/local.db)");
  cmd_->add_flag("--json", *shared_.json, "machine-readable output on stdout");
  AddServerOptions(cmd_, shared_);  // on a server, prune needs an admin token
}

int PruneCli::Run() {
  auto age = ParseAge(older_than_);
  if (!age.ok()) return Fail(age.status());
  if (keep_last_ < 0) return Fail(Status::InvalidArgument("--keep-last: must be >= 0"));
  const bool local = local_ || shared_.server->empty();
  auto out = local ? PruneLocal(*shared_.store_path, *age, keep_last_, dry_run_)
                   : PruneRemote(shared_, *age, keep_last_, dry_run_);
  if (!out.ok()) return Fail(out.status());
  Print(*out, local ? server::LocalService::Describe(*shared_.store_path) : "server " + *shared_.server, *shared_.json);
  return kExitOk;
}

}  // namespace vb::benchctl
