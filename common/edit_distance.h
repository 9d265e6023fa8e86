// The edit distance (Levenshtein: insertions, deletions, substitutions) behind every "did you mean": benchctl's
// misspelt options (benchctl/main.cc) and a spec's misspelt fields (experiment/spec.cc).
#pragma once

#include <cstddef>
#include <string_view>

namespace vb {

// ignore_case: letters differing only in case count as the same (a field differing only in case is the closest
// there is).
std::size_t EditDistance(std::string_view a, std::string_view b, bool ignore_case = false);

}  // namespace vb
