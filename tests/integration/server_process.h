// Starts the real valvebench-server binary on a loopback port with a temporary database and config, for
// integration tests; kills it (SIGTERM or SIGKILL) on request or at the end.
#pragma once

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "service/auth.h"
#include "valvebench/v1/config.pb.h"

extern char** environ;

namespace vb::testing {

// Tokens the fixture configures: one per role.
// The smallest valid server configuration: one emulated bench "emu" and a viewer whose token is "x" (config
// validation tests add the block under test).
inline valvebench::v1::ServerConfig MinimalConfig() {
  valvebench::v1::ServerConfig c;
  auto* b = c.add_benches();
  b->set_name("emu");
  b->mutable_model()->set_preset("taghizadeh2009");
  auto* t = c.add_tokens();
  t->set_user("v");
  t->set_role("viewer");
  t->set_token_sha256(vb::server::Sha256Hex("x"));
  return c;
}

// Writes into `dir` examples/suites/ci.json and its hold spec with the PI law's proportional gain cut tenfold (a
// worse controller that regresses against the committed baseline; docs/regress.md says why not the integral gain
// since issue 37). Returns "" or what went wrong.
inline std::string WriteWorseCiSuite(const std::string& suites_dir, const std::string& dir) {
  std::filesystem::create_directories(dir);
  std::filesystem::copy_file(suites_dir + "ci.json", dir + "/ci.json", std::filesystem::copy_options::overwrite_existing);
  std::ifstream in(suites_dir + "ci-current-hold.json");
  std::stringstream ss;
  ss << in.rdbuf();
  std::string spec = ss.str();
  const size_t law = spec.find("\"pi_current\": {}", spec.find("\"name\": \"pi\""));
  if (law == std::string::npos) return "ci-current-hold.json has no pi variant with an empty pi_current";
  spec.replace(law, 16, R"("pi_current": {"kp_V_per_A": 37.7})");
  std::ofstream(dir + "/ci-current-hold.json") << spec;
  return "";
}

inline constexpr const char* kViewerToken = "viewer-token-1";
inline constexpr const char* kOperatorToken = "operator-token-1";
inline constexpr const char* kOperator2Token = "operator-token-2";
inline constexpr const char* kAdminToken = "admin-token-1";

class ServerProcess {
 public:
  // dir: a fresh directory for config, database and logs (kept across restarts). extra_fields: more top-level
  // config fields, e.g. R"("limits": {...})" or R"("tls": {...})".
  // benches: the "benches" array's JSON, two emulated benches unless given.
  explicit ServerProcess(std::string dir, std::string extra_fields = "",
                         std::string benches = R"([{"name": "emu-a", "kind": "emulated", "model": {"preset": "taghizadeh2009"}},
                  {"name": "emu-b", "kind": "emulated", "model": {"preset": "taghizadeh2009"}}])")
      : dir_(std::move(dir)) {
    std::filesystem::create_directories(dir_);
    std::ofstream cfg(dir_ + "/server.json");
    cfg << R"({"listen_address": "127.0.0.1:0", "database_path": "runs.db", "benches": )" << benches << R"(,
      "tokens": [)"
        << Token("viewer", "viewer", kViewerToken) << "," << Token("olga", "operator", kOperatorToken) << ","
        << Token("oscar", "operator", kOperator2Token) << "," << Token("ada", "admin", kAdminToken) << "]"
        << (extra_fields.empty() ? "" : ", " + extra_fields) << "}";
  }
  ~ServerProcess() { Kill(SIGKILL); }

  // Starts the server and waits until it listens; returns "127.0.0.1:<port>" or "" on failure.
  std::string Start() {
    const std::string log = dir_ + "/server-" + std::to_string(++starts_) + ".log";
    log_ = log;
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 2, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_addopen(&fa, 1, "/dev/null", O_WRONLY, 0);
    const std::string config = dir_ + "/server.json";
    std::vector<char*> argv = {const_cast<char*>(VB_SERVER), const_cast<char*>("--config"),
                               const_cast<char*>(config.c_str())};
    for (auto& a : extra_args_) argv.push_back(a.data());
    argv.push_back(nullptr);
    const int rc = posix_spawn(&pid_, VB_SERVER, &fa, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&fa);
    if (rc != 0) return "";
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(20);
    while (std::chrono::steady_clock::now() < until) {
      std::ifstream in(log);
      std::stringstream ss;
      ss << in.rdbuf();
      const std::string text = ss.str();
      const auto at = text.find("listening on ");
      if (at != std::string::npos) {
        const auto end = text.find(' ', at + 13);
        address_ = text.substr(at + 13, end - at - 13);
        return address_;
      }
      int status = 0;
      if (waitpid(pid_, &status, WNOHANG) == pid_) {
        pid_ = 0;
        return "";
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return "";
  }

  // Sends sig and waits for the process; returns its exit status (as waitpid reports it).
  int Kill(int sig) {
    if (pid_ <= 0) return -1;
    ::kill(pid_, sig);
    int status = 0;
    waitpid(pid_, &status, 0);
    pid_ = 0;
    return status;
  }

  // Sends sig without waiting (SIGSTOP, SIGCONT).
  void Signal(int sig) {
    if (pid_ > 0) ::kill(pid_, sig);
  }

  // More command-line arguments for the next Start(), e.g. "--run-night-now".
  void AddArg(std::string arg) { extra_args_.push_back(std::move(arg)); }
  const std::string& address() const { return address_; }
  std::string Log() const {
    std::ifstream in(log_);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
  }
  std::string db_path() const { return dir_ + "/runs.db"; }
  const std::string& dir() const { return dir_; }
  pid_t pid() const { return pid_; }  // 0 when not running

 private:
  static std::string Token(const char* user, const char* role, const char* token) {
    return std::string(R"({"user": ")") + user + R"(", "role": ")" + role + R"(", "token_sha256": ")" +
           server::Sha256Hex(token) + R"("})";
  }
  std::string dir_;
  std::string log_;
  std::string address_;
  pid_t pid_ = 0;
  int starts_ = 0;
  std::vector<std::string> extra_args_;
};

}  // namespace vb::testing
