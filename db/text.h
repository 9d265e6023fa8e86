// Cat("run ", id, " not found"): builds a message by appending pieces (strings, string_views, C strings, chars,
// integers). Used instead of `"literal" + std::to_string(x)`, whose operator+(const char*, std::string&&)
// trips GCC 12's -Wrestrict false positive at -O3 (GCC bug 105329) in some inlining contexts.
// Doubles are not accepted: format them explicitly (the store uses "%.17g").
#pragma once

#include <string>
#include <string_view>
#include <type_traits>

namespace vb::db {
namespace text_internal {

inline void Append(std::string* out, std::string_view s) { out->append(s.data(), s.size()); }
inline void Append(std::string* out, char c) { out->push_back(c); }
template <typename T>
  requires(std::is_integral_v<T> && !std::is_same_v<T, char> && !std::is_same_v<T, bool>)
void Append(std::string* out, T v) {
  Append(out, std::string_view(std::to_string(v)));
}

}  // namespace text_internal

template <typename... Args>
std::string Cat(const Args&... args) {
  std::string out;
  (text_internal::Append(&out, args), ...);
  return out;
}

}  // namespace vb::db
