// Plots of a report page as SVG and PNG files (docs/report.md "Exporting plots"): the page is rendered by
// Debian's headless chromium (scripts/setup.sh installs it), its drawn DOM read back, each plot written as a
// standalone SVG with its styles inlined, and each SVG screenshotted by the same browser for the PNG.
#include <unistd.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <regex>
#include <string>

#include "report/report.h"

namespace vb::report {
namespace {

namespace fs = std::filesystem;

std::string Quoted(const std::string& s) {  // for /bin/sh: '...' with ' as '\''
  std::string out = "'";
  for (char c : s) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

StatusOr<std::string> Chromium() {
  for (const char* p : {"/usr/bin/chromium", "/usr/bin/chromium-browser"})
    if (::access(p, X_OK) == 0) return std::string(p);
  return Status::Unavailable("--svg/--png need Debian's chromium (headless; scripts/setup.sh installs it): "
                             "apt-get install chromium");
}

StatusOr<std::string> Run(const std::string& cmd) {
  FILE* f = ::popen(cmd.c_str(), "r");
  if (f == nullptr) return Status::Unavailable("cannot start: " + cmd);
  std::string out;
  std::array<char, 65536> buf;
  for (size_t n; (n = std::fread(buf.data(), 1, buf.size(), f)) > 0;) out.append(buf.data(), n);
  const int rc = ::pclose(f);
  if (rc != 0) return Status::Unavailable("chromium failed (exit " + std::to_string(rc) + ")");
  return out;
}

std::string Slug(const std::string& s) {
  std::string out;
  for (char c : s) {
    if (std::isalnum(static_cast<unsigned char>(c))) {
      out += static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    } else if (!out.empty() && out.back() != '-') {
      out += '-';
    }
    if (out.size() >= 48) break;
  }
  while (!out.empty() && out.back() == '-') out.pop_back();
  return out.empty() ? "plot" : out;
}

constexpr const char* kSvgStyle =
    "<style>text{font:11px sans-serif;fill:#333}.grid{stroke:#eee}.axis{stroke:#999;fill:none}"
    ".band{fill:rgba(255,200,0,0.16)}.sel{display:none}</style>";

}  // namespace

StatusOr<std::vector<std::string>> ExportPlots(const std::string& html_path, const std::string& svg_dir,
                                               const std::string& png_dir) {
  auto chromium = Chromium();
  if (!chromium.ok()) return chromium.status();
  std::error_code ec;
  const fs::path html = fs::absolute(html_path, ec);
  const fs::path profile = fs::temp_directory_path() / ("vb-report-export-" + std::to_string(::getpid()));
  const std::string browser = *chromium + " --headless --no-sandbox --disable-gpu --hide-scrollbars --user-data-dir=" +
                              Quoted(profile.string()) + " 2>/dev/null ";
  // '#all-svg': the page draws every run's traces, not only the first ones, as SVG (page.cc: dygraphs draws on a
  // canvas, which has no vector form).
  auto dom = Run(browser + "--dump-dom " + Quoted("file://" + html.string() + "#all-svg"));
  if (!dom.ok()) return dom.status();
  const std::string svg_out = svg_dir.empty() ? (fs::temp_directory_path() / ("vb-svg-" + std::to_string(::getpid()))).string() : svg_dir;
  fs::create_directories(svg_out, ec);
  if (ec) return Status::Unavailable(svg_out + ": cannot create the directory: " + ec.message());
  if (!png_dir.empty()) {
    fs::create_directories(png_dir, ec);
    if (ec) return Status::Unavailable(png_dir + ": cannot create the directory: " + ec.message());
  }
  std::vector<std::string> written;
  std::string heading = "plot";
  const std::regex tag(R"(<(?:h[23]|summary)[^>]*>([^<]*)</(?:h[23]|summary)>|<svg [^>]*class="plot"[^>]*>)");
  size_t pos = 0;
  int n = 0;
  for (std::sregex_iterator it(dom->begin(), dom->end(), tag), end; it != end; ++it) {
    const std::smatch& m = *it;
    if (m[1].matched) {
      heading = m[1].str();
      continue;
    }
    const size_t start = static_cast<size_t>(m.position(0));
    if (start < pos) continue;
    const size_t close = dom->find("</svg>", start);
    if (close == std::string::npos) break;
    pos = close + 6;
    std::string svg = dom->substr(start, pos - start);
    std::smatch vb;
    double w = 1200, h = 300;
    if (std::regex_search(svg, vb, std::regex(R"(viewBox="0 0 ([0-9.]+) ([0-9.]+)\")"))) {
      w = std::stod(vb[1].str());
      h = std::stod(vb[2].str());
    }
    // Standalone: the SVG namespace, a size, and the page's plot styles.
    svg.replace(0, 4, "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" + std::to_string(static_cast<int>(w)) +
                          "\" height=\"" + std::to_string(static_cast<int>(h)) + "\"");
    svg.insert(svg.find('>') + 1, kSvgStyle);
    char name[16];
    std::snprintf(name, sizeof name, "%02d-", ++n);
    const std::string base = name + Slug(heading);
    const fs::path svg_file = fs::path(svg_out) / (base + ".svg");
    std::ofstream(svg_file) << "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n" << svg << "\n";
    if (!svg_dir.empty()) written.push_back(svg_file.string());
    if (!png_dir.empty()) {
      const fs::path png = fs::absolute(fs::path(png_dir) / (base + ".png"), ec);
      auto shot = Run(browser + "--window-size=" + std::to_string(static_cast<int>(w)) + "," +
                      std::to_string(static_cast<int>(h)) + " --screenshot=" + Quoted(png.string()) + " " +
                      Quoted("file://" + fs::absolute(svg_file).string()));
      if (!shot.ok()) return shot.status();
      if (!fs::exists(png)) return Status::Unavailable(png.string() + ": chromium wrote no screenshot");
      written.push_back(png.string());
    }
  }
  fs::remove_all(profile, ec);
  if (svg_dir.empty()) fs::remove_all(svg_out, ec);
  if (n == 0) return Status::FailedPrecondition(html_path + ": the page has no plots to export");
  return written;
}

}  // namespace vb::report
