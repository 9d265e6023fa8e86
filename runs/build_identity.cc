#include "runs/build_identity.h"

#include <openssl/evp.h>

#include <array>
#include <cstdio>
#include <memory>

#include <fmt/format.h>

#ifndef VB_PROJECT_VERSION
#error "VB_PROJECT_VERSION must be defined by the build (runs/CMakeLists.txt)"
#endif

namespace vb::runs {
namespace {

std::string HashOwnExecutable() {
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> f(std::fopen("/proc/self/exe", "rb"), &std::fclose);
  if (!f) return "";
  std::unique_ptr<EVP_MD_CTX, void (*)(EVP_MD_CTX*)> ctx(EVP_MD_CTX_new(), &EVP_MD_CTX_free);
  if (!ctx || EVP_DigestInit_ex(ctx.get(), EVP_sha256(), nullptr) != 1) return "";
  std::array<unsigned char, 1 << 16> buf;
  for (;;) {
    const std::size_t n = std::fread(buf.data(), 1, buf.size(), f.get());
    if (n > 0 && EVP_DigestUpdate(ctx.get(), buf.data(), n) != 1) return "";
    if (n < buf.size()) break;
  }
  if (std::ferror(f.get())) return "";
  std::array<unsigned char, EVP_MAX_MD_SIZE> digest;
  unsigned int len = 0;
  if (EVP_DigestFinal_ex(ctx.get(), digest.data(), &len) != 1 || len < 16) return "";
  std::string hex;
  for (unsigned int k = 0; k < 16; ++k) hex += fmt::format("{:02x}", digest[k]);
  return fmt::format("valvebench {} sha256:{}", VB_PROJECT_VERSION, hex);
}

}  // namespace

const std::string& ThisBuild() {
  static const std::string build = HashOwnExecutable();
  return build;
}

std::string BuildDigest(const std::string& build) {
  const auto at = build.find(" sha256:");
  if (at == std::string::npos) return "";
  const std::string digest = build.substr(at + 1);
  return digest.size() > 7 ? digest : "";
}

}  // namespace vb::runs
