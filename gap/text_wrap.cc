#include "gap/text_wrap.h"

#include <sstream>

namespace vb::gap {

std::string Wrap(const std::vector<std::string>& items, std::size_t indent, std::size_t width, std::size_t first) {
  std::string out, line;
  auto pad = [&]() { return out.empty() && first != std::string::npos ? first : indent; };
  for (const auto& item : items) {
    std::istringstream in(item);
    std::string word;
    bool first_word = true;
    while (in >> word) {
      const std::string piece = (first_word && !line.empty() ? "  " : line.empty() ? "" : " ") + word;
      if (!line.empty() && pad() + line.size() + piece.size() > width) {
        out += std::string(pad(), ' ') + line + "\n";
        line = word;
      } else {
        line += piece;
      }
      first_word = false;
    }
  }
  if (!line.empty()) out += std::string(pad(), ' ') + line + "\n";
  return out;
}

std::string Hanging(const std::string& prefix, const std::string& text, std::size_t width) {
  const std::size_t col = prefix.size();
  // A prefix wider than half the line leaves too little room: the text then goes under it, indented by 4.
  if (col > width / 2) return prefix + "\n" + Wrap({text}, 4, width);
  std::string w = Wrap({text}, col, width > col + 20 ? width : col + 20, col);
  if (w.empty()) return prefix + "\n";
  return prefix + w.substr(col);
}

}  // namespace vb::gap
