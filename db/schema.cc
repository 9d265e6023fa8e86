#include "db/schema.h"

#include "db/text.h"

namespace vb::db::schema {
namespace {

// Version 1: the initial schema. Times are unix seconds (REAL); statuses are their RunStatusName() text so
// that the file reads well in the sqlite3 shell. docs/store.md explains every table and index.
constexpr const char* kV1 = R"sql(
CREATE TABLE batches (
  id        INTEGER PRIMARY KEY AUTOINCREMENT,
  submitter TEXT NOT NULL,
  name      TEXT NOT NULL,
  spec_json TEXT NOT NULL,
  created   REAL NOT NULL
);

CREATE TABLE runs (
  id                   INTEGER PRIMARY KEY AUTOINCREMENT,
  batch_id             INTEGER NOT NULL REFERENCES batches (id),
  name                 TEXT NOT NULL,
  controller           TEXT NOT NULL,
  bench_kind           TEXT NOT NULL,
  requested_bench      TEXT NOT NULL,
  bench_name           TEXT NOT NULL,
  spec_json            TEXT NOT NULL,
  submitter            TEXT NOT NULL,
  priority             INTEGER NOT NULL,
  status               TEXT NOT NULL
                       CHECK (status IN ('queued', 'running', 'done', 'failed', 'cancelled', 'interrupted')),
  reason               TEXT NOT NULL DEFAULT '',
  requeue_on_interrupt INTEGER NOT NULL CHECK (requeue_on_interrupt IN (0, 1)),
  cancel_requested     INTEGER NOT NULL DEFAULT 0 CHECK (cancel_requested IN (0, 1)),
  submitted            REAL NOT NULL,
  started              REAL NOT NULL DEFAULT 0,
  finished             REAL NOT NULL DEFAULT 0,
  progress             REAL NOT NULL DEFAULT 0
);
CREATE INDEX runs_queue     ON runs (status, priority DESC, id);
CREATE INDEX runs_batch     ON runs (batch_id, id);
CREATE INDEX runs_submitter ON runs (submitter, status);
CREATE INDEX runs_controller ON runs (controller);
CREATE INDEX runs_bench     ON runs (bench_name);
CREATE INDEX runs_submitted ON runs (submitted);

CREATE TABLE run_tags (
  run_id INTEGER NOT NULL REFERENCES runs (id) ON DELETE CASCADE,
  tag    TEXT NOT NULL,
  UNIQUE (run_id, tag)
);
CREATE INDEX run_tags_tag ON run_tags (tag, run_id);

CREATE TABLE status_history (
  id     INTEGER PRIMARY KEY,
  run_id INTEGER NOT NULL REFERENCES runs (id) ON DELETE CASCADE,
  status TEXT NOT NULL
         CHECK (status IN ('queued', 'running', 'done', 'failed', 'cancelled', 'interrupted')),
  at     REAL NOT NULL,
  reason TEXT NOT NULL DEFAULT ''
);
CREATE INDEX status_history_run ON status_history (run_id, id);

CREATE TABLE metrics (
  run_id INTEGER NOT NULL REFERENCES runs (id) ON DELETE CASCADE,
  name   TEXT NOT NULL,
  value  REAL,
  PRIMARY KEY (run_id, name)
) WITHOUT ROWID;

CREATE TABLE trace_chunks (
  run_id   INTEGER NOT NULL REFERENCES runs (id) ON DELETE CASCADE,
  idx      INTEGER NOT NULL CHECK (idx >= 0),
  t0       REAL NOT NULL,
  period   REAL NOT NULL,
  samples  INTEGER NOT NULL CHECK (samples > 0),
  channels TEXT NOT NULL,
  data     BLOB NOT NULL,
  PRIMARY KEY (run_id, idx)
);
)sql";

// Version 2. A baseline version is immutable: (name, version) is unique and nothing updates or deletes rows, so
// `baseline set` under an existing name can only add version n+1. Metric rows like the runs' metrics table.
constexpr const char* kV2 = R"sql(
CREATE TABLE baselines (
  id       INTEGER PRIMARY KEY AUTOINCREMENT,
  name     TEXT NOT NULL CHECK (length(name) > 0),
  version  INTEGER NOT NULL CHECK (version >= 1),
  created  REAL NOT NULL,
  source   TEXT NOT NULL DEFAULT '',
  note     TEXT NOT NULL DEFAULT '',
  UNIQUE (name, version)
);

CREATE TABLE baseline_metrics (
  baseline_id INTEGER NOT NULL REFERENCES baselines (id) ON DELETE CASCADE,
  case_name   TEXT NOT NULL,
  metric      TEXT NOT NULL,
  mean        REAL NOT NULL,
  spread      REAL NOT NULL CHECK (spread >= 0),
  n           INTEGER NOT NULL CHECK (n >= 1),
  PRIMARY KEY (baseline_id, case_name, metric)
) WITHOUT ROWID;

CREATE TABLE regressions (
  id               INTEGER PRIMARY KEY AUTOINCREMENT,
  suite            TEXT NOT NULL,
  baseline_name    TEXT NOT NULL,
  baseline_version INTEGER NOT NULL,
  batch_id         INTEGER NOT NULL DEFAULT 0,
  night            TEXT NOT NULL DEFAULT '',
  created          REAL NOT NULL,
  verdict          TEXT NOT NULL,
  result_json      TEXT NOT NULL
);
CREATE INDEX regressions_night ON regressions (night, id);
)sql";

// Version 3. A run's identity as fields (common/run_key.h) instead of text: the spec name (`key_name`), the
// repeat (`repeat_index`, -1 = not repeated) and the sweep point as typed rows of `run_sweep`; imported runs'
// `split` and `t_start_s` (NULL for other runs). `name` stays as the run's display name for readers of the
// file. Rows written before version 3 are filled in from the tags that carried these ("sweep:<field>=<value>",
// "repeat:<k>", "split:<s>", "t_start_s:<t>"): the one place that tag text is ever read, once.
constexpr const char* kV3 = R"sql(
ALTER TABLE runs ADD COLUMN key_name TEXT NOT NULL DEFAULT '';
ALTER TABLE runs ADD COLUMN repeat_index INTEGER NOT NULL DEFAULT -1 CHECK (repeat_index >= -1);
ALTER TABLE runs ADD COLUMN split TEXT NOT NULL DEFAULT '' CHECK (split IN ('', 'fit', 'holdout'));
ALTER TABLE runs ADD COLUMN t_start_s REAL;

CREATE TABLE run_sweep (
  run_id INTEGER NOT NULL REFERENCES runs (id) ON DELETE CASCADE,
  axis   INTEGER NOT NULL CHECK (axis >= 0),
  field  TEXT NOT NULL,
  value  REAL NOT NULL,
  PRIMARY KEY (run_id, axis)
) WITHOUT ROWID;

UPDATE runs SET key_name = CASE
  WHEN instr(name, ' sweep:') > 0 THEN substr(name, 1, instr(name, ' sweep:') - 1)
  WHEN instr(name, ' repeat:') > 0 THEN substr(name, 1, instr(name, ' repeat:') - 1)
  ELSE name END;
UPDATE runs SET repeat_index = (SELECT CAST(substr(tag, 8) AS INTEGER) FROM run_tags
                                WHERE run_tags.run_id = runs.id AND substr(tag, 1, 7) = 'repeat:' LIMIT 1)
  WHERE EXISTS (SELECT 1 FROM run_tags WHERE run_tags.run_id = runs.id AND substr(tag, 1, 7) = 'repeat:');
INSERT INTO run_sweep (run_id, axis, field, value)
  SELECT run_id, ROW_NUMBER() OVER (PARTITION BY run_id ORDER BY rowid) - 1,
         substr(tag, 7, instr(tag, '=') - 7), CAST(substr(tag, instr(tag, '=') + 1) AS REAL)
  FROM run_tags WHERE substr(tag, 1, 6) = 'sweep:' AND instr(tag, '=') > 0;
UPDATE runs SET split = (SELECT substr(tag, 7) FROM run_tags
                         WHERE run_tags.run_id = runs.id AND tag IN ('split:fit', 'split:holdout') LIMIT 1)
  WHERE EXISTS (SELECT 1 FROM run_tags WHERE run_tags.run_id = runs.id AND tag IN ('split:fit', 'split:holdout'));
UPDATE runs SET t_start_s = (SELECT CAST(substr(tag, 11) AS REAL) FROM run_tags
                             WHERE run_tags.run_id = runs.id AND substr(tag, 1, 10) = 't_start_s:' LIMIT 1)
  WHERE bench_kind = 'imported';
)sql";

// Version 4. Trace chunks say how their data is encoded (db/trace_codec.h): 0 = raw little-endian float64, what
// every chunk stored before this version is, so they stay readable as they are; the store writes 1 (per-channel
// transform, byte shuffle, zstd) from now on. Nothing is rewritten: a migration that recompressed gigabytes
// inside Open()'s one transaction would hold the write lock for minutes (docs/store.md, "Schema version 4").
constexpr const char* kV4 = R"sql(
ALTER TABLE trace_chunks ADD COLUMN codec INTEGER NOT NULL DEFAULT 0 CHECK (codec IN (0, 1));
)sql";

// Version 5. The lab (docs/lab.md): several server processes ("hosts") share one store. A run carries the fencing
// token of the attempt that holds it (`fence`, incremented by every claim), the host executing it and when its
// lease lapses (`lease_expires`, unix s; 0 = no lease). `hosts` is one row per server process with its
// heartbeat; `stale_writes` logs every write the store refused because its fence was no longer the run's;
// `nights_claimed` lets exactly one host run each scheduled night.
constexpr const char* kV5 = R"sql(
ALTER TABLE runs ADD COLUMN fence INTEGER NOT NULL DEFAULT 0 CHECK (fence >= 0);
ALTER TABLE runs ADD COLUMN host TEXT NOT NULL DEFAULT '';
ALTER TABLE runs ADD COLUMN lease_expires REAL NOT NULL DEFAULT 0;
CREATE INDEX runs_host ON runs (status, host);

CREATE TABLE hosts (
  name         TEXT PRIMARY KEY CHECK (length(name) > 0),
  address      TEXT NOT NULL DEFAULT '',
  benches_json TEXT NOT NULL DEFAULT '[]',
  started      REAL NOT NULL,
  heartbeat    REAL NOT NULL
) WITHOUT ROWID;

CREATE TABLE stale_writes (
  id            INTEGER PRIMARY KEY,
  run_id        INTEGER NOT NULL REFERENCES runs (id) ON DELETE CASCADE,
  fence         INTEGER NOT NULL,
  current_fence INTEGER NOT NULL,
  host          TEXT NOT NULL DEFAULT '',
  what          TEXT NOT NULL,
  at            REAL NOT NULL
);
CREATE INDEX stale_writes_run ON stale_writes (run_id);

CREATE TABLE nights_claimed (
  night TEXT PRIMARY KEY,
  host  TEXT NOT NULL,
  at    REAL NOT NULL
) WITHOUT ROWID;
)sql";

// Version 6. What executing a run measured travels with the run (docs/store.md, "Schema version 6"): its wall
// time, experiment time covered, samples, control ticks and the metrics' source (exec_*), and for a paced
// (realtime) run its loop statistics (loop_*: ticks, overruns, wake-up lateness p50/p99/max). Finish writes them
// in the transaction that ends the run. NULL means "not measured": every run finished before this version, runs
// that never executed, and the loop_* columns of a run whose loop was not paced. Nothing is backfilled.
constexpr const char* kV6 = R"sql(
ALTER TABLE runs ADD COLUMN exec_wall_s REAL CHECK (exec_wall_s >= 0);
ALTER TABLE runs ADD COLUMN exec_simulated_s REAL CHECK (exec_simulated_s >= 0);
ALTER TABLE runs ADD COLUMN exec_samples INTEGER CHECK (exec_samples >= 0);
ALTER TABLE runs ADD COLUMN exec_control_ticks INTEGER CHECK (exec_control_ticks >= 0);
ALTER TABLE runs ADD COLUMN exec_metrics_from_trajectory INTEGER CHECK (exec_metrics_from_trajectory IN (0, 1));
ALTER TABLE runs ADD COLUMN loop_ticks INTEGER CHECK (loop_ticks >= 0);
ALTER TABLE runs ADD COLUMN loop_overruns INTEGER CHECK (loop_overruns >= 0);
ALTER TABLE runs ADD COLUMN loop_jitter_p50_s REAL;
ALTER TABLE runs ADD COLUMN loop_jitter_p99_s REAL;
ALTER TABLE runs ADD COLUMN loop_jitter_max_s REAL;
)sql";

// Version 7. Which build executed a run (docs/store.md, "Schema version 7"): the version and the digest of the
// executable (runs::ThisBuild), written by Finish with the exec_* columns. NULL: not known (every run finished
// before this version). The bench twin compares it with the baseline's runs' (docs/track.md).
constexpr const char* kV7 = R"sql(
ALTER TABLE runs ADD COLUMN exec_build TEXT;
)sql";

constexpr Migration kMigrations[] = {
    {1, "initial schema: batches, runs, run_tags, status_history, metrics, trace_chunks", kV1},
    {2, "baselines, baseline_metrics, regressions (benchctl baseline / regress / nights)",
     kV2},
    {3, "runs: key_name, repeat_index, split, t_start_s; run_sweep (a run's identity as fields)", kV3},
    {4, "trace_chunks: codec (compressed traces; older chunks stay raw float64)", kV4},
    {5, "runs: fence, host, lease_expires; hosts, stale_writes, nights_claimed (the lab)", kV5},
    {6, "runs: exec_* and loop_* (what executing a run measured, its loop statistics)", kV6},
    {7, "runs: exec_build (which build executed the run)", kV7},
};

}  // namespace

std::span<const Migration> Migrations() { return kMigrations; }
int CurrentVersion() { return kMigrations[std::size(kMigrations) - 1].version; }

StatusOr<int> ReadVersion(sql::Connection* conn) {
  VB_ASSIGN_OR_RETURN(const std::int64_t v, conn->QueryInt("PRAGMA user_version"));
  return static_cast<int>(v);
}

Status CheckKnown(int version, std::span<const Migration> migrations, const std::string& path) {
  const int known = migrations.empty() ? 0 : migrations.back().version;
  if (version > known) {
    return Status::FailedPrecondition(Cat("database '", path, "' has schema version ", version,
                                          ", newer than this build knows (", known,
                                          "); use a newer valvebench (the file was left untouched)"));
  }
  if (version < 0) {
    return Status::DataLoss(
        Cat("database '", path, "' has schema version ", version, " (user_version must not be negative)"));
  }
  return Status::Ok();
}

StatusOr<int> Migrate(sql::Connection* conn, std::span<const Migration> migrations, const std::string& path) {
  for (std::size_t k = 0; k < migrations.size(); ++k) {
    if (migrations[k].version != static_cast<int>(k) + 1) {
      return Status::Internal(Cat("migration ", k, " has version ", migrations[k].version, ", expected ", k + 1));
    }
  }
  const std::string where = Cat("database '", path, "'");
  sql::Transaction txn(conn);
  VB_RETURN_IF_ERROR(txn.Begin(sql::Transaction::Kind::kWrite).WithContext(where));
  StatusOr<int> read = ReadVersion(conn);
  if (!read.ok()) return read.status().WithContext(where);
  int version = *read;
  VB_RETURN_IF_ERROR(CheckKnown(version, migrations, path));
  for (const Migration& m : migrations) {
    if (m.version <= version) continue;
    VB_RETURN_IF_ERROR(conn->Exec(m.sql).WithContext(
        Cat(where, ": schema migration to version ", m.version, " (", m.description, ")")));
    // PRAGMA takes no bound parameters; the value is our own integer.
    VB_RETURN_IF_ERROR(conn->Exec(Cat("PRAGMA user_version = ", m.version)).WithContext(where));
    version = m.version;
  }
  VB_RETURN_IF_ERROR(txn.Commit().WithContext(where));
  return version;
}

}  // namespace vb::db::schema
