// Bearer-token authentication with roles. Tokens are stored only as SHA-256 hex digests (in the config);
// a presented token is hashed and compared in constant time.
//   viewer:   read everything (runs, traces, comparisons, benches)
//   operator: viewer + submit runs, cancel their own
//   admin:    everything, including cancelling anyone's runs
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include "common/status.h"
#include "valvebench/v1/config.pb.h"

namespace vb::server {

enum class Role { kViewer = 0, kOperator = 1, kAdmin = 2 };
const char* RoleName(Role r);

struct Principal {
  std::string user;
  Role role = Role::kViewer;
  bool AtLeast(Role r) const { return static_cast<int>(role) >= static_cast<int>(r); }
};

std::string Sha256Hex(std::string_view data);

class Authenticator {
 public:
  // Validates the entries (known role, 64 hex digits, unique users): errors name "tokens[i].field".
  static StatusOr<Authenticator> Create(const google::protobuf::RepeatedPtrField<valvebench::v1::TokenConfig>& tokens);
  // `authorization` is the metadata value, "Bearer <token>". Unauthenticated statuses carry no token text.
  StatusOr<Principal> Authenticate(std::string_view authorization) const;

 private:
  struct Entry {
    std::string user;
    Role role;
    std::string sha256_hex;
  };
  std::vector<Entry> entries_;
};

}  // namespace vb::server
