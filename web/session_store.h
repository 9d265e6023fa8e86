#pragma once
// The web dashboard's sessions (docs/web.md "Sessions"), kept in a file so that they survive a restart of the
// server (issue 39, point 4): stored, revocable, expiring.
//
// A session is a random 256-bit id in the browser's HttpOnly cookie, standing for a bearer token the server
// checked at login. The file holds neither: each record has
//   - id_sha256: SHA-256 of the id (with a domain prefix), the key a cookie is looked up by;
//   - sealed: the token encrypted with AES-256-GCM under a key derived from the id itself (SHA-256 of the id with
//     another prefix), so that the file alone opens no session and reveals no token: only a browser holding the
//     cookie can, as before the restart;
//   - token_sha256: SHA-256 of the token, for the per-token cap and "log out everywhere" (tokens are random and
//     long; the server's configuration stores the same kind of hash);
//   - user, created_unix_s, expires_unix_s: who, and the wall clock's end (a steady clock does not survive a
//     restart; a clock stepped by hand moves the end with it).
// The file is rewritten whole on every change (at most kMaxPerToken sessions per configured token: a few KB),
// through a temporary file, fsync and rename, mode 0600. Empty path: in memory only (the behaviour before).
#include <cstddef>
#include <map>
#include <mutex>
#include <string>
#include <vector>

namespace vb::web {

class SessionStore {
 public:
  static constexpr std::size_t kMaxPerToken = 32;
  static constexpr double kDefaultLife_s = 12 * 3600;

  // Reads `path` if it exists. A file that cannot be read or parsed is moved aside (path + ".unreadable") with a
  // warning naming it and the problem, and the store starts empty: a damaged file costs a login, not the server.
  explicit SessionStore(std::string path = "", double life_s = kDefaultLife_s);

  // A new session for a token the service accepted; returns its id (64 hex digits) for the cookie. A token's
  // oldest session goes when it has kMaxPerToken.
  std::string Create(const std::string& token, const std::string& user);
  // The token a live session stands for, or "" (unknown, expired, or its record does not open with this id).
  std::string TokenOf(const std::string& id);
  // Logout: this session only. Returns whether it existed.
  bool Revoke(const std::string& id);
  // "Log out everywhere": every session of the token this session stands for; returns how many went.
  std::size_t RevokeAllOf(const std::string& id);

  std::size_t Size();
  double life_s() const { return life_s_; }
  const std::string& path() const { return path_; }
  // Seconds since the epoch; a test moves it to see sessions expire.
  void SetClockForTest(double (*now_unix_s)()) { now_ = now_unix_s; }

 private:
  struct Record {
    std::string token_sha256;
    std::string sealed;  // hex: 12-byte nonce, ciphertext, 16-byte tag
    std::string user;
    double created_unix_s = 0;
    double expires_unix_s = 0;
  };
  void Load();
  void PruneLocked();
  void SaveLocked();

  std::string path_;
  double life_s_;
  double (*now_)();
  std::mutex mu_;
  std::map<std::string, Record> by_id_hash_;
};

}  // namespace vb::web
