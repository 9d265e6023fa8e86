#include "benchctl/db_commands.h"

#include <chrono>
#include <cstdio>
#include <nlohmann/json.hpp>

#include "benchctl/backend.h"
#include "benchctl/cli_common.h"
#include "service/store_admin.h"

namespace vb::benchctl {
namespace {

using Json = nlohmann::ordered_json;

std::string Bytes(std::int64_t b) {
  char buf[32];
  if (b >= 1'000'000'000)
    std::snprintf(buf, sizeof buf, "%.2f GB", b / 1e9);
  else if (b >= 1'000'000)
    std::snprintf(buf, sizeof buf, "%.1f MB", b / 1e6);
  else if (b >= 1'000)
    std::snprintf(buf, sizeof buf, "%.1f kB", b / 1e3);
  else
    std::snprintf(buf, sizeof buf, "%lld B", static_cast<long long>(b));
  return buf;
}

}  // namespace

DbCli::DbCli(CLI::App* app, SharedOptions shared) : shared_(shared) {
  cmd_ = app->add_subcommand("db", "the store itself: info, copy a SQLite store into PostgreSQL");
  cmd_->require_subcommand(1);
  info_ = cmd_->add_subcommand("info", "engine, schema version, runs by status, rows, trace bytes");
  info_->add_option("--db", *shared_.store_path,
                    "the store: a SQLite file or a PostgreSQL connection string "
                    "(default $VALVEBENCH_DB or ~/.local/share/valvebench/local.db); given, it wins over a server");
  info_->add_flag("--local", local_, "the local store, even if a server is configured");
  AddServerOptions(info_, shared_);
  info_->add_flag("--json", *shared_.json, "machine-readable output on stdout");
  copy_ = cmd_->add_subcommand("copy", "copy a SQLite store's history into PostgreSQL, keeping ids");
  copy_->add_option("--from", from_, "the SQLite store file")->required();
  copy_->add_option("--to", to_, "the PostgreSQL database: postgresql://... or \"host=... dbname=...\"")->required();
  copy_->add_flag("--into-non-empty", into_non_empty_, "copy even if the target holds runs (no id may collide)");
  copy_->add_flag("--json", *shared_.json, "machine-readable output on stdout");
}

int DbCli::Run(const ClientFactory& make_client) {
  const bool json = *shared_.json;
  if (info_->parsed()) {
    const std::string& store_path = *shared_.store_path;
    // A store named with --db is that store, whatever server is configured: db info is about a store.
    const bool named = info_->count("--db") > 0;
    const std::string server = (local_ || named) ? "" : *shared_.server;
    if (server.empty() && store_path.empty())
      return Fail(Status::InvalidArgument("--db: give the store (a file or postgresql://...)"));
    auto backend = ChooseBackend(server, store_path, make_client);  // reads only: executes nothing
    auto info = backend->DescribeStore();
    if (!info.ok()) return Fail(info.status());
    if (json) {
      Json j;
      j["engine"] = info->engine();
      j["location"] = info->location();
      j["schema_version"] = info->schema_version();
      Json by_status = Json::object();
      for (const auto& c : info->runs_by_status()) by_status[c.name()] = c.count();
      j["runs_by_status"] = by_status;
      Json rows = Json::object();
      for (const auto& c : info->rows()) rows[c.name()] = c.count();
      j["rows"] = rows;
      j["trace_bytes"] = info->trace_bytes();
      std::printf("%s\n", j.dump(2).c_str());
      return kExitOk;
    }
    std::printf("engine          %s\nlocation        %s\nschema version  %d\n", info->engine().c_str(),
                info->location().c_str(), info->schema_version());
    std::printf("runs           ");
    for (const auto& c : info->runs_by_status())
      std::printf(" %s %lld", c.name().c_str(), static_cast<long long>(c.count()));
    std::printf("\n");
    for (const auto& c : info->rows())
      std::printf("%-15s %lld rows\n", c.name().c_str(), static_cast<long long>(c.count()));
    std::printf("trace data      %s (as stored, compressed)\n", Bytes(info->trace_bytes()).c_str());
    return kExitOk;
  }
  if (copy_->parsed()) {
    const auto t0 = std::chrono::steady_clock::now();
    auto summary = server::CopyStoreToPostgres(from_, to_, into_non_empty_);
    if (!summary.ok()) return Fail(summary.status());
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (json) {
      Json j;
      j["from"] = from_;
      j["source_schema_version"] = summary->source_version;
      j["target_schema_version"] = summary->target_version;
      Json rows = Json::object();
      for (const auto& [t, n] : summary->rows) rows[t] = n;
      j["rows"] = rows;
      j["trace_bytes"] = summary->trace_bytes;
      j["seconds"] = seconds;
      std::printf("%s\n", j.dump(2).c_str());
      return kExitOk;
    }
    std::printf("copied %s into PostgreSQL (schema %d -> %d) in %.2f s:\n", from_.c_str(), summary->source_version,
                summary->target_version, seconds);
    for (const auto& [t, n] : summary->rows) std::printf("  %-17s %lld rows\n", t.c_str(), static_cast<long long>(n));
    std::printf("  trace data        %s as stored\n", Bytes(summary->trace_bytes).c_str());
    return kExitOk;
  }
  return kExitBadInput;
}

}  // namespace vb::benchctl
