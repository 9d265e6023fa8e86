#include "client/trace_csv.h"

#include <algorithm>
#include <vector>

#include "common/csv.h"

namespace vb::client {

std::string TraceCsvHeader(const TraceColumns& trace) {
  std::string out = "t_s";
  for (const auto& name : trace.channels)
    if (name != "t_s") out.append(",").append(name);
  out += '\n';
  return out;
}

namespace {

// Rows [from, to) of `rows`.
void AppendRows(const TraceColumns& rows, std::int64_t first_row, std::size_t from, std::size_t to, std::string* out) {
  const std::vector<double>* time = rows.Find("t_s");
  std::vector<const std::vector<double>*> cols;
  for (const auto& name : rows.channels)
    if (name != "t_s") cols.push_back(rows.Find(name));
  out->reserve(out->size() + (to - from) * (cols.size() + 1) * 14);
  for (std::size_t i = from; i < to; ++i) {
    // The stored time column, else each row's own time (decimated rows), else the time base.
    double t = 0.0;
    if (time != nullptr) {
      t = (*time)[i];
    } else if (!rows.t_s.empty()) {
      t = rows.t_s[i];
    } else {
      t = rows.t0_s + static_cast<double>(first_row + static_cast<std::int64_t>(i)) * rows.sample_period_s;
    }
    AppendCsvNumber(out, t);
    for (const auto* col : cols) {
      *out += ',';
      AppendCsvNumber(out, (*col)[i]);
    }
    *out += '\n';
  }
}

bool Write(const std::string& text, std::FILE* f) { return std::fwrite(text.data(), 1, text.size(), f) == text.size(); }

}  // namespace

void AppendTraceCsvRows(const TraceColumns& rows, std::int64_t first_row, std::string* out) {
  AppendRows(rows, first_row, 0, rows.samples(), out);
}

std::string TraceCsv(const TraceColumns& trace) {
  std::string out = TraceCsvHeader(trace);
  AppendTraceCsvRows(trace, 0, &out);
  return out;
}

Status WriteTraceCsv(const TraceColumns& trace, std::FILE* f, const std::string& what) {
  constexpr std::size_t kBlockRows = 65536;
  std::string out = TraceCsvHeader(trace);
  const std::size_t n = trace.samples();
  for (std::size_t from = 0; from < n || !out.empty(); from += kBlockRows) {
    if (from < n) AppendRows(trace, 0, from, std::min(n, from + kBlockRows), &out);
    if (!Write(out, f)) return Status::DataLoss(what + ": write failed");
    out.clear();
  }
  if (std::fflush(f) != 0 || std::ferror(f)) return Status::DataLoss(what + ": write failed");
  return Status::Ok();
}

Status WriteTraceCsv(TraceStream& stream, std::FILE* f, const std::string& what) {
  std::string out = TraceCsvHeader(stream.rows());
  bool more = true;
  while (more) {
    AppendTraceCsvRows(stream.rows(), stream.first_row(), &out);
    stream.DropRows();
    if (!Write(out, f)) {
      stream.Abandon();
      return Status::DataLoss(what + ": write failed");
    }
    out.clear();
    more = stream.Next();
  }
  if (!stream.status().ok()) return stream.status();
  if (std::fflush(f) != 0 || std::ferror(f)) return Status::DataLoss(what + ": write failed");
  return Status::Ok();
}

}  // namespace vb::client
