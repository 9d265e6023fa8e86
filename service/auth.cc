#include "service/auth.h"

#include <openssl/evp.h>

#include <cctype>
#include <set>

namespace vb::server {

const char* RoleName(Role r) {
  switch (r) {
    case Role::kViewer: return "viewer";
    case Role::kOperator: return "operator";
    case Role::kAdmin: return "admin";
  }
  return "viewer";
}

std::string Sha256Hex(std::string_view data) {
  unsigned char digest[EVP_MAX_MD_SIZE];
  unsigned int len = 0;
  EVP_Digest(data.data(), data.size(), digest, &len, EVP_sha256(), nullptr);
  static const char* kHex = "0123456789abcdef";
  std::string out;
  out.reserve(2 * len);
  for (unsigned int k = 0; k < len; ++k) {
    out.push_back(kHex[digest[k] >> 4]);
    out.push_back(kHex[digest[k] & 0xF]);
  }
  return out;
}

StatusOr<Authenticator> Authenticator::Create(
    const google::protobuf::RepeatedPtrField<valvebench::v1::TokenConfig>& tokens) {
  Authenticator a;
  std::set<std::string> users;
  for (int k = 0; k < tokens.size(); ++k) {
    const auto& t = tokens[k];
    const std::string field = "tokens[" + std::to_string(k) + "]";
    if (t.user().empty()) return Status::InvalidArgument(field + ".user: must not be empty");
    if (!users.insert(t.user()).second) return Status::InvalidArgument(field + ".user: '" + t.user() + "' appears twice");
    Role role;
    if (t.role() == "viewer") {
      role = Role::kViewer;
    } else if (t.role() == "operator") {
      role = Role::kOperator;
    } else if (t.role() == "admin") {
      role = Role::kAdmin;
    } else {
      return Status::InvalidArgument(field + ".role: '" + t.role() + "' is not one of viewer, operator, admin");
    }
    std::string hex = t.token_sha256();
    for (char& c : hex) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    if (hex.size() != 64 || hex.find_first_not_of("0123456789abcdef") != std::string::npos)
      return Status::InvalidArgument(field + ".token_sha256: must be 64 hex digits (sha256sum of the token)");
    a.entries_.push_back({t.user(), role, hex});
  }
  return a;
}

StatusOr<Principal> Authenticator::Authenticate(std::string_view authorization) const {
  constexpr std::string_view kBearer = "Bearer ";
  if (authorization.substr(0, kBearer.size()) != kBearer || authorization.size() == kBearer.size())
    return Status::FailedPrecondition("missing or malformed authorization metadata (expected 'Bearer <token>')");
  const std::string hex = Sha256Hex(authorization.substr(kBearer.size()));
  for (const auto& e : entries_) {
    unsigned diff = 0;  // constant-time comparison of equal-length digests
    for (size_t k = 0; k < hex.size(); ++k) diff |= static_cast<unsigned>(hex[k] ^ e.sha256_hex[k]);
    if (diff == 0) return Principal{e.user, e.role};
  }
  return Status::FailedPrecondition("unknown token");
}

}  // namespace vb::server
