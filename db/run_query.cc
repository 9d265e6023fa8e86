#include "db/run_query.h"

#include <bit>
#include <cmath>
#include <cstdio>
#include <cstring>

#include "db/text.h"

namespace vb::db {
namespace {

struct SortField {
  RunSortKey key;
  std::string_view name;
};
constexpr SortField kSortFields[] = {
    {RunSortKey::kId, "id"},
    {RunSortKey::kSubmitted, "submitted"},
    {RunSortKey::kStarted, "started"},
    {RunSortKey::kFinished, "finished"},
    {RunSortKey::kDuration, "duration"},
    {RunSortKey::kName, "name"},
    {RunSortKey::kStatus, "status"},
    {RunSortKey::kBench, "bench"},
    {RunSortKey::kController, "controller"},
    {RunSortKey::kSubmitter, "submitter"},
};

std::string_view FieldName(RunSortKey key) {
  for (const SortField& f : kSortFields)
    if (f.key == key) return f.name;
  return "id";
}

enum class KeyType { kInt, kDouble, kText };
KeyType TypeOf(RunSortKey key) {
  switch (key) {
    case RunSortKey::kId:
    case RunSortKey::kStatus: return KeyType::kInt;
    case RunSortKey::kSubmitted:
    case RunSortKey::kStarted:
    case RunSortKey::kFinished:
    case RunSortKey::kDuration: return KeyType::kDouble;
    default: return KeyType::kText;
  }
}

// The lifecycle rank kStatus sorts by; the SQL below computes the same.
int StatusRank(RunStatus s) {
  switch (s) {
    case RunStatus::kQueued: return 0;
    case RunStatus::kRunning: return 1;
    case RunStatus::kInterrupted: return 2;
    case RunStatus::kDone: return 3;
    case RunStatus::kFailed: return 4;
    case RunStatus::kCancelled: return 5;
  }
  return 5;
}

std::string_view Trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t')) s.remove_suffix(1);
  return s;
}

std::string FieldList() {
  std::string out;
  for (const SortField& f : kSortFields) out += Cat(out.empty() ? "" : ", ", f.name);
  return out;
}

// ---- Page tokens ----

constexpr char kB64[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789-_";

std::string Base64Url(std::string_view in) {
  std::string out;
  std::uint32_t acc = 0;
  int bits = 0;
  for (unsigned char c : in) {
    acc = (acc << 8) | c;
    bits += 8;
    while (bits >= 6) {
      bits -= 6;
      out.push_back(kB64[(acc >> bits) & 63]);
    }
  }
  if (bits > 0) out.push_back(kB64[(acc << (6 - bits)) & 63]);
  return out;
}

bool FromBase64Url(std::string_view in, std::string* out) {
  std::uint32_t acc = 0;
  int bits = 0;
  for (char c : in) {
    const char* at = std::strchr(kB64, c);
    if (c == '\0' || at == nullptr) return false;
    acc = (acc << 6) | static_cast<std::uint32_t>(at - kB64);
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out->push_back(static_cast<char>((acc >> bits) & 0xff));
    }
  }
  return true;
}

// FNV-1a over the filters and the order a token belongs to (not the cursor, not the page size).
std::uint64_t Fingerprint(const RunFilter& f) {
  std::string s;
  auto field = [&s](std::string_view v) {
    s += Cat(v.size(), ':');
    s.append(v);
  };
  field(f.status ? RunStatusName(*f.status) : "");
  field(f.tag);
  field(Cat(f.batch_id));
  field(f.controller);
  field(f.bench_name);
  field(f.submitter);
  field(f.name);
  field(Cat(std::bit_cast<std::uint64_t>(f.submitted_after_unix_s)));
  field(Cat(std::bit_cast<std::uint64_t>(f.submitted_before_unix_s)));
  field(Cat(f.after_id));
  field(RunOrderText(f.order));
  std::uint64_t h = 1469598103934665603ull;
  for (unsigned char c : s) {
    h ^= c;
    h *= 1099511628211ull;
  }
  return h;
}

constexpr std::string_view kTokenVersion = "r1";

}  // namespace

const std::vector<std::string_view>& RunSortFields() {
  static const std::vector<std::string_view> names = [] {
    std::vector<std::string_view> v;
    for (const SortField& f : kSortFields) v.push_back(f.name);
    return v;
  }();
  return names;
}

StatusOr<RunOrder> ParseRunOrder(std::string_view order_by) {
  const std::string_view text = Trim(order_by);
  if (text.empty()) return RunOrder{RunSortKey::kSubmitted, true};
  std::string_view field = text, direction;
  if (const std::size_t sp = text.find_first_of(" \t"); sp != std::string_view::npos) {
    field = text.substr(0, sp);
    direction = Trim(text.substr(sp));
  }
  auto bad = [&](std::string_view why) {
    return Status::InvalidArgument(Cat("order_by: ", why, " in '", text, "'; expected \"FIELD\" or \"FIELD desc\" with "
                                       "FIELD one of ", FieldList()));
  };
  if (text.find(',') != std::string_view::npos) return bad("only one field can be ordered by");
  RunOrder order;
  bool known = false;
  for (const SortField& f : kSortFields) {
    if (f.name == field) {
      order.key = f.key;
      known = true;
    }
  }
  if (!known) return bad(Cat("unknown field '", field, "'"));
  if (direction == "desc") {
    order.desc = true;
  } else if (!direction.empty() && direction != "asc") {
    return bad(Cat("unknown direction '", direction, "'"));
  }
  return order;
}

std::string RunOrderText(const RunOrder& order) {
  return Cat(FieldName(order.key), order.desc ? " desc" : "");
}

RunCursor CursorAfter(const RunRecord& run, const RunOrder& order) {
  RunCursor c;
  c.id = run.id;
  switch (order.key) {
    case RunSortKey::kId: c.number = static_cast<double>(run.id); break;
    case RunSortKey::kSubmitted: c.number = run.submitted_unix_s; break;
    case RunSortKey::kStarted: c.number = run.started_unix_s; break;
    case RunSortKey::kFinished: c.number = run.finished_unix_s; break;
    case RunSortKey::kDuration:
      // As the SQL computes it (run_query::Page): the same IEEE subtraction.
      c.number = run.started_unix_s > 0 && run.finished_unix_s > 0 ? run.finished_unix_s - run.started_unix_s : 0.0;
      break;
    case RunSortKey::kStatus: c.number = StatusRank(run.status); break;
    case RunSortKey::kName: c.text = run.key.DisplayName(); break;
    case RunSortKey::kBench: c.text = run.bench_name; break;
    case RunSortKey::kController: c.text = run.controller; break;
    case RunSortKey::kSubmitter: c.text = run.submitter; break;
  }
  return c;
}

std::string EncodePageToken(const RunFilter& filter, const RunRecord& last) {
  const RunCursor c = CursorAfter(last, filter.order);
  char fp[17];
  std::snprintf(fp, sizeof fp, "%016llx", static_cast<unsigned long long>(Fingerprint(filter)));
  // version|fingerprint|order|id|number's bits|text (the text last: it may contain '|').
  return Base64Url(Cat(kTokenVersion, '|', std::string_view(fp), '|', RunOrderText(filter.order), '|', c.id, '|',
                       std::bit_cast<std::uint64_t>(c.number), '|', c.text));
}

Status ApplyPageToken(std::string_view token, RunFilter* filter) {
  if (token.empty()) return Status::Ok();
  const Status bad = Status::InvalidArgument("page_token: not a token from a previous ListRuns");
  std::string raw;
  if (!FromBase64Url(token, &raw)) return bad;
  std::vector<std::string> parts;
  std::size_t from = 0;
  for (int k = 0; k < 5; ++k) {
    const std::size_t bar = raw.find('|', from);
    if (bar == std::string::npos) return bad;
    parts.push_back(raw.substr(from, bar - from));
    from = bar + 1;
  }
  parts.push_back(raw.substr(from));
  if (parts[0] != kTokenVersion) return bad;
  char fp[17];
  std::snprintf(fp, sizeof fp, "%016llx", static_cast<unsigned long long>(Fingerprint(*filter)));
  if (parts[1] != fp) {
    return Status::InvalidArgument(
        Cat("page_token: was made for other filters or another order_by (it continues a listing in order '",
            parts[2], "'); ask again from the first page with these filters"));
  }
  RunCursor c;
  char* end = nullptr;
  c.id = std::strtoll(parts[3].c_str(), &end, 10);
  if (parts[3].empty() || *end != '\0' || c.id < 0) return bad;
  const unsigned long long bits = std::strtoull(parts[4].c_str(), &end, 10);
  if (parts[4].empty() || *end != '\0') return bad;
  c.number = std::bit_cast<double>(static_cast<std::uint64_t>(bits));
  if (!std::isfinite(c.number)) return bad;
  c.text = std::move(parts[5]);
  filter->after = std::move(c);
  return Status::Ok();
}

namespace run_query {
namespace {

// The SQL of the sort key (the same on both engines but for the collation of text keys).
std::string KeySql(RunSortKey key, Dialect d) {
  const char* collate = d == Dialect::kPostgres ? " COLLATE \"C\"" : "";
  switch (key) {
    case RunSortKey::kId: return "id";
    case RunSortKey::kSubmitted: return "submitted";
    case RunSortKey::kStarted: return "started";
    case RunSortKey::kFinished: return "finished";
    case RunSortKey::kDuration: return "(CASE WHEN started > 0 AND finished > 0 THEN finished - started ELSE 0 END)";
    case RunSortKey::kStatus:
      return "(CASE status WHEN 'queued' THEN 0 WHEN 'running' THEN 1 WHEN 'interrupted' THEN 2 "
             "WHEN 'done' THEN 3 WHEN 'failed' THEN 4 ELSE 5 END)";
    case RunSortKey::kName: return Cat("name", collate);
    case RunSortKey::kBench: return Cat("bench_name", collate);
    case RunSortKey::kController: return Cat("controller", collate);
    case RunSortKey::kSubmitter: return Cat("submitter", collate);
  }
  return "id";
}

class Builder {
 public:
  explicit Builder(Dialect d) : d_(d) {}
  // The next placeholder, bound to v.
  std::string Bind(Param v) {
    q_.params.push_back(std::move(v));
    return Cat(d_ == Dialect::kPostgres ? "$" : "?", q_.params.size());
  }
  void Add(std::string_view sql) { q_.sql.append(sql); }
  Query Take() { return std::move(q_); }

 private:
  Dialect d_;
  Query q_;
};

// The filters' conditions, joined by AND after " FROM runs". No condition for a filter not in use: an unfiltered
// count(*) is then a scan of the smallest index, not of the table with its specs.
void Where(const RunFilter& f, Dialect d, Builder* b) {
  b->Add(" FROM runs");
  bool first = true;
  auto cond = [&](const std::string& sql) {
    b->Add(Cat(first ? " WHERE " : " AND ", sql));
    first = false;
  };
  if (f.after_id > 0) cond(Cat("id > ", b->Bind(f.after_id)));
  if (f.status) cond(Cat("status = ", b->Bind(std::string(RunStatusName(*f.status)))));
  if (!f.tag.empty()) cond(Cat("id IN (SELECT run_id FROM run_tags WHERE tag = ", b->Bind(f.tag), ")"));
  if (f.batch_id != 0) cond(Cat("batch_id = ", b->Bind(f.batch_id)));
  if (!f.controller.empty()) cond(Cat("controller = ", b->Bind(f.controller)));
  if (!f.bench_name.empty()) cond(Cat("bench_name = ", b->Bind(f.bench_name)));
  if (!f.submitter.empty()) cond(Cat("submitter = ", b->Bind(f.submitter)));
  if (!f.name.empty()) {
    // ASCII case folding on both engines (SQLite's lower() folds ASCII only; "C" makes PostgreSQL's do the same).
    cond(d == Dialect::kPostgres
             ? Cat("strpos(lower(name COLLATE \"C\"), lower(", b->Bind(f.name), " COLLATE \"C\")) > 0")
             : Cat("instr(lower(name), lower(", b->Bind(f.name), ")) > 0"));
  }
  if (f.submitted_after_unix_s > 0) cond(Cat("submitted >= ", b->Bind(f.submitted_after_unix_s)));
  if (f.submitted_before_unix_s > 0) cond(Cat("submitted < ", b->Bind(f.submitted_before_unix_s)));
  // Keyset paging (Page only): the rows after the cursor in (key, id) order, both in the listing's direction.
  if (f.after) {
    const char* cmp = f.order.desc ? "<" : ">";
    if (f.order.key == RunSortKey::kId) {
      cond(Cat("id ", cmp, " ", b->Bind(f.after->id)));
    } else {
      Param value;
      switch (TypeOf(f.order.key)) {
        case KeyType::kInt: value = static_cast<std::int64_t>(f.after->number); break;
        case KeyType::kDouble: value = f.after->number; break;
        case KeyType::kText: value = f.after->text; break;
      }
      const std::string v = b->Bind(std::move(value));
      cond(Cat("(", KeySql(f.order.key, d), ", id) ", cmp, " (", v, ", ", b->Bind(f.after->id), ")"));
    }
  }
}

}  // namespace

Query Page(const RunFilter& f, Dialect d) {
  Builder b(d);
  Where(f, d, &b);
  const std::string key = KeySql(f.order.key, d);
  const char* dir = f.order.desc ? " DESC" : "";
  if (f.order.key == RunSortKey::kId) {
    b.Add(Cat(" ORDER BY id", dir));
  } else {
    b.Add(Cat(" ORDER BY ", key, dir, ", id", dir));
  }
  b.Add(Cat(" LIMIT ", b.Bind(static_cast<std::int64_t>(f.limit))));
  return b.Take();
}

Query Count(const RunFilter& f, Dialect d) {
  RunFilter all = f;
  all.after.reset();  // every page
  Builder b(d);
  Where(all, d, &b);
  return b.Take();
}

}  // namespace run_query
}  // namespace vb::db
