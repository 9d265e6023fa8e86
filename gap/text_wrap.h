// Reports that fit a 120-column terminal: words wrapped onto indented lines (the diagnosis, the identification).
#pragma once

#include <cstddef>
#include <string>
#include <vector>

namespace vb::gap {

// Words (each item split further at spaces; items joined by two spaces) on lines of at most `width` columns,
// each indented by `indent` (the first by `first`, when given: a hanging indent). Ends with a newline unless empty.
std::string Wrap(const std::vector<std::string>& items, std::size_t indent, std::size_t width = 120,
                 std::size_t first = std::string::npos);

// `prefix` (kept as it is, e.g. aligned columns) followed by `text` wrapped under the text's first column.
std::string Hanging(const std::string& prefix, const std::string& text, std::size_t width = 120);

}  // namespace vb::gap
