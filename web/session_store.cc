#include "web/session_store.h"

#include <fcntl.h>
#include <fmt/format.h>
#include <openssl/evp.h>
#include <openssl/rand.h>
#include <openssl/sha.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>
#include <stdexcept>

namespace vb::web {
namespace {

using Json = nlohmann::json;

double SystemNow_s() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

std::string Hex(const unsigned char* p, std::size_t n) {
  static const char* digits = "0123456789abcdef";
  std::string out(2 * n, '0');
  for (std::size_t k = 0; k < n; ++k) {
    out[2 * k] = digits[p[k] >> 4];
    out[2 * k + 1] = digits[p[k] & 15];
  }
  return out;
}

bool Unhex(const std::string& s, std::string* out) {
  if (s.size() % 2 != 0) return false;
  out->clear();
  for (std::size_t k = 0; k < s.size(); k += 2) {
    auto nibble = [](char c) -> int {
      if (c >= '0' && c <= '9') return c - '0';
      if (c >= 'a' && c <= 'f') return c - 'a' + 10;
      return -1;
    };
    const int hi = nibble(s[k]), lo = nibble(s[k + 1]);
    if (hi < 0 || lo < 0) return false;
    out->push_back(static_cast<char>(hi * 16 + lo));
  }
  return true;
}

// SHA-256 of a domain prefix and the text: the lookup key and the sealing key come from the same id under
// different prefixes, so the stored lookup key says nothing about the sealing key.
std::string Sha256(std::string_view prefix, std::string_view text) {
  std::string in(prefix);
  in += text;
  unsigned char digest[SHA256_DIGEST_LENGTH];
  SHA256(reinterpret_cast<const unsigned char*>(in.data()), in.size(), digest);
  return std::string(reinterpret_cast<const char*>(digest), sizeof(digest));
}
std::string IdHash(const std::string& id) {
  const std::string h = Sha256("valvebench web session id v1\n", id);
  return Hex(reinterpret_cast<const unsigned char*>(h.data()), h.size());
}
std::string TokenHash(const std::string& token) {
  const std::string h = Sha256("valvebench web session token v1\n", token);
  return Hex(reinterpret_cast<const unsigned char*>(h.data()), h.size());
}

struct CipherCtx {
  EVP_CIPHER_CTX* p = EVP_CIPHER_CTX_new();
  ~CipherCtx() { EVP_CIPHER_CTX_free(p); }
};
constexpr int kNonce = 12, kTag = 16;

// AES-256-GCM of the token under SHA-256("...key...", id); the id hash is the associated data, so a record's
// sealed token cannot be moved to another record.
std::string Seal(const std::string& id, const std::string& token) {
  const std::string key = Sha256("valvebench web session key v1\n", id);
  const std::string aad = IdHash(id);
  unsigned char nonce[kNonce];
  if (RAND_bytes(nonce, kNonce) != 1) throw std::runtime_error("session: no random bytes for a nonce");
  CipherCtx c;
  std::string out(token.size() + 16, '\0');
  int n = 0, m = 0;
  unsigned char tag[kTag];
  if (c.p == nullptr || EVP_EncryptInit_ex(c.p, EVP_aes_256_gcm(), nullptr, nullptr, nullptr) != 1 ||
      EVP_CIPHER_CTX_ctrl(c.p, EVP_CTRL_GCM_SET_IVLEN, kNonce, nullptr) != 1 ||
      EVP_EncryptInit_ex(c.p, nullptr, nullptr, reinterpret_cast<const unsigned char*>(key.data()), nonce) != 1 ||
      EVP_EncryptUpdate(c.p, nullptr, &n, reinterpret_cast<const unsigned char*>(aad.data()),
                        static_cast<int>(aad.size())) != 1 ||
      EVP_EncryptUpdate(c.p, reinterpret_cast<unsigned char*>(out.data()), &n,
                        reinterpret_cast<const unsigned char*>(token.data()), static_cast<int>(token.size())) != 1 ||
      EVP_EncryptFinal_ex(c.p, reinterpret_cast<unsigned char*>(out.data()) + n, &m) != 1 ||
      EVP_CIPHER_CTX_ctrl(c.p, EVP_CTRL_GCM_GET_TAG, kTag, tag) != 1)
    throw std::runtime_error("session: AES-256-GCM failed");
  out.resize(static_cast<std::size_t>(n + m));
  return Hex(nonce, kNonce) + Hex(reinterpret_cast<const unsigned char*>(out.data()), out.size()) + Hex(tag, kTag);
}

// The token, or "" when the record does not open with this id (another id, or an altered record).
std::string Open(const std::string& id, const std::string& sealed_hex) {
  std::string raw;
  if (!Unhex(sealed_hex, &raw) || raw.size() < kNonce + kTag) return "";
  const std::string key = Sha256("valvebench web session key v1\n", id);
  const std::string aad = IdHash(id);
  const auto* bytes = reinterpret_cast<const unsigned char*>(raw.data());
  const int ct_len = static_cast<int>(raw.size()) - kNonce - kTag;
  CipherCtx c;
  std::string out(static_cast<std::size_t>(ct_len) + 16, '\0');
  int n = 0, m = 0;
  unsigned char tag[kTag];
  std::memcpy(tag, bytes + kNonce + ct_len, kTag);
  if (c.p == nullptr || EVP_DecryptInit_ex(c.p, EVP_aes_256_gcm(), nullptr, nullptr, nullptr) != 1 ||
      EVP_CIPHER_CTX_ctrl(c.p, EVP_CTRL_GCM_SET_IVLEN, kNonce, nullptr) != 1 ||
      EVP_DecryptInit_ex(c.p, nullptr, nullptr, reinterpret_cast<const unsigned char*>(key.data()), bytes) != 1 ||
      EVP_DecryptUpdate(c.p, nullptr, &n, reinterpret_cast<const unsigned char*>(aad.data()),
                        static_cast<int>(aad.size())) != 1 ||
      EVP_DecryptUpdate(c.p, reinterpret_cast<unsigned char*>(out.data()), &n, bytes + kNonce, ct_len) != 1 ||
      EVP_CIPHER_CTX_ctrl(c.p, EVP_CTRL_GCM_SET_TAG, kTag, tag) != 1 ||
      EVP_DecryptFinal_ex(c.p, reinterpret_cast<unsigned char*>(out.data()) + n, &m) != 1)
    return "";
  out.resize(static_cast<std::size_t>(n + m));
  return out;
}

bool IsHex64(const std::string& s) {
  return s.size() == 64 && std::all_of(s.begin(), s.end(), [](char c) {
           return (c >= '0' && c <= '9') || (c >= 'a' && c <= 'f');
         });
}

}  // namespace

SessionStore::SessionStore(std::string path, double life_s)
    : path_(std::move(path)), life_s_(life_s), now_(&SystemNow_s) {
  if (!path_.empty()) Load();
}

void SessionStore::Load() {
  std::error_code exists_ec;
  if (!std::filesystem::exists(path_, exists_ec)) return;  // the first start: no sessions yet
  std::ifstream in(path_, std::ios::binary);
  if (!in) {
    spdlog::warn("web sessions: cannot read {} ({}); starting with none", path_, std::strerror(errno));
    return;
  }
  std::stringstream text;
  text << in.rdbuf();
  std::string problem;
  std::map<std::string, Record> loaded;
  try {
    const Json doc = Json::parse(text.str());
    if (!doc.is_object() || doc.value("version", 0) != 1 || !doc.contains("sessions") || !doc["sessions"].is_array())
      throw std::runtime_error("not a version 1 sessions file (an object with \"version\": 1 and \"sessions\": [...])");
    std::size_t k = 0;
    for (const Json& s : doc["sessions"]) {
      const std::string where = fmt::format("sessions[{}]", k++);
      if (!s.is_object()) throw std::runtime_error(where + ": must be an object");
      for (const char* field : {"id_sha256", "token_sha256", "sealed", "user"})
        if (!s.contains(field) || !s[field].is_string())
          throw std::runtime_error(where + "." + field + ": must be a string");
      for (const char* field : {"created_unix_s", "expires_unix_s"})
        if (!s.contains(field) || !s[field].is_number() || !std::isfinite(s[field].get<double>()))
          throw std::runtime_error(where + "." + field + ": must be a finite number");
      const std::string id_hash = s["id_sha256"].get<std::string>();
      if (!IsHex64(id_hash)) throw std::runtime_error(where + ".id_sha256: must be 64 lower-case hex digits");
      if (!IsHex64(s["token_sha256"].get<std::string>()))
        throw std::runtime_error(where + ".token_sha256: must be 64 lower-case hex digits");
      Record r{s["token_sha256"].get<std::string>(), s["sealed"].get<std::string>(), s["user"].get<std::string>(),
               s["created_unix_s"].get<double>(), s["expires_unix_s"].get<double>()};
      loaded[id_hash] = std::move(r);
    }
  } catch (const std::exception& e) {
    problem = e.what();
  }
  if (!problem.empty()) {
    const std::string aside = path_ + ".unreadable";
    std::error_code ec;
    std::filesystem::rename(path_, aside, ec);
    spdlog::warn("web sessions: {}: {}; moved to {}{}; starting with none (users log in again)", path_, problem, aside,
                 ec ? " failed (" + ec.message() + ")" : "");
    return;
  }
  std::lock_guard<std::mutex> lock(mu_);
  by_id_hash_ = std::move(loaded);
  const std::size_t before = by_id_hash_.size();
  PruneLocked();
  if (by_id_hash_.size() != before) SaveLocked();
  spdlog::info("web sessions: {} kept from {} ({} expired)", by_id_hash_.size(), path_, before - by_id_hash_.size());
}

std::string SessionStore::Create(const std::string& token, const std::string& user) {
  unsigned char raw[32];
  if (RAND_bytes(raw, sizeof(raw)) != 1) throw std::runtime_error("no random bytes for a session id");
  const std::string id = Hex(raw, sizeof(raw));
  const double now = now_();
  Record r{TokenHash(token), Seal(id, token), user, now, now + life_s_};
  std::lock_guard<std::mutex> lock(mu_);
  PruneLocked();
  // A token's own oldest session goes when it has kMaxPerToken (issue 34: 24,000 logins of one user evicted
  // everyone's sessions). Only a token the service accepted logs in, so the total is bounded by the configured
  // tokens times kMaxPerToken.
  for (;;) {
    std::size_t mine = 0;
    auto oldest = by_id_hash_.end();
    for (auto it = by_id_hash_.begin(); it != by_id_hash_.end(); ++it) {
      if (it->second.token_sha256 != r.token_sha256) continue;
      ++mine;
      if (oldest == by_id_hash_.end() || it->second.created_unix_s < oldest->second.created_unix_s) oldest = it;
    }
    if (mine < kMaxPerToken) break;
    by_id_hash_.erase(oldest);
  }
  by_id_hash_[IdHash(id)] = std::move(r);
  SaveLocked();
  return id;
}

std::string SessionStore::TokenOf(const std::string& id) {
  if (id.empty()) return "";
  const std::string key = IdHash(id);
  std::lock_guard<std::mutex> lock(mu_);
  auto it = by_id_hash_.find(key);
  if (it == by_id_hash_.end()) return "";
  if (now_() > it->second.expires_unix_s) {
    by_id_hash_.erase(it);
    SaveLocked();
    return "";
  }
  return Open(id, it->second.sealed);
}

bool SessionStore::Revoke(const std::string& id) {
  std::lock_guard<std::mutex> lock(mu_);
  if (by_id_hash_.erase(IdHash(id)) == 0) return false;
  SaveLocked();
  return true;
}

std::size_t SessionStore::RevokeAllOf(const std::string& id) {
  std::lock_guard<std::mutex> lock(mu_);
  auto it = by_id_hash_.find(IdHash(id));
  if (it == by_id_hash_.end()) return 0;
  const std::string token_hash = it->second.token_sha256;
  const std::size_t n = std::erase_if(by_id_hash_, [&](const auto& kv) { return kv.second.token_sha256 == token_hash; });
  SaveLocked();
  return n;
}

std::size_t SessionStore::Size() {
  std::lock_guard<std::mutex> lock(mu_);
  PruneLocked();
  return by_id_hash_.size();
}

void SessionStore::PruneLocked() {
  const double now = now_();
  std::erase_if(by_id_hash_, [now](const auto& kv) { return now > kv.second.expires_unix_s; });
}

// The whole file anew: a temporary beside it (mode 0600), written, fsync'ed and renamed over, then the directory
// fsync'ed, so a crash leaves the old file or the new one. A failed write is logged and the sessions stay in
// memory: logging in never fails for the file's sake.
void SessionStore::SaveLocked() {
  if (path_.empty()) return;
  Json list = Json::array();
  for (const auto& [id_hash, r] : by_id_hash_)
    list.push_back({{"id_sha256", id_hash},
                    {"token_sha256", r.token_sha256},
                    {"sealed", r.sealed},
                    {"user", r.user},
                    {"created_unix_s", r.created_unix_s},
                    {"expires_unix_s", r.expires_unix_s}});
  const std::string text = Json{{"version", 1}, {"sessions", std::move(list)}}.dump(1) + "\n";
  const std::string tmp = path_ + ".tmp";
  std::string problem;
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
  if (fd < 0) {
    problem = "cannot create " + tmp + ": " + std::strerror(errno);
  } else {
    std::size_t done = 0;
    while (done < text.size()) {
      const ssize_t w = ::write(fd, text.data() + done, text.size() - done);
      if (w < 0 && errno == EINTR) continue;
      if (w <= 0) {
        problem = "cannot write " + tmp + ": " + std::strerror(errno);
        break;
      }
      done += static_cast<std::size_t>(w);
    }
    if (problem.empty() && ::fsync(fd) != 0) problem = "cannot fsync " + tmp + ": " + std::strerror(errno);
    ::close(fd);
    if (problem.empty() && std::rename(tmp.c_str(), path_.c_str()) != 0)
      problem = "cannot rename " + tmp + " to " + path_ + ": " + std::strerror(errno);
  }
  if (!problem.empty()) {
    ::unlink(tmp.c_str());
    spdlog::warn("web sessions: {} (the sessions stay in memory: a restart would end them)", problem);
    return;
  }
  const std::string dir = std::filesystem::path(path_).parent_path().string();
  const int dfd = ::open(dir.empty() ? "." : dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dfd >= 0) {
    ::fsync(dfd);
    ::close(dfd);
  }
}

}  // namespace vb::web
