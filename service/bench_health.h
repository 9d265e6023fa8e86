// The bench twin's stored history (docs/track.md "On the server"): each bench's nightly identified values, as
// the nights scheduler keeps them in each night's record (regressions table, result JSON "health"), read back
// for the next night's tracking (server/nights.cc) and for GetBenchHealth.
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "common/status.h"
#include "db/store.h"
#include "gap/track.h"
#include "regress/compare.h"
#include "valvebench/v1/api.pb.h"

namespace vb::server {

// A bench's checked night as stored: when the night started and its health check's batch.
struct StoredCheck {
  double night_started_unix_s = 0.0;  // 0: not recorded
  std::int64_t batch_id = 0;
};

// Where a bench's anchor moved to (the server's basin check, server/bench_twin.h): the anchor's internal values and
// effects as a warm start reads them (gap::MovingIdentification::fitted, effects), stored in the night it moved.
struct StoredAnchor {
  std::string night;  // the night it moved
  std::string anchor_night;
  std::map<std::string, double> fitted;
  std::vector<std::string> effects;
  int moves = 0;  // how often it has moved
};

struct StoredHealth {
  // bench -> night -> values; a night whose record holds "reidentified" (the anchor moved that night) gives the
  // values of every earlier night as identified again from the moved anchor: the newest such night's stand.
  std::map<std::string, std::map<std::string, gap::SessionValues>> values;
  std::map<std::string, std::pair<std::string, std::int64_t>> first_check;  // bench -> (night, batch)
  std::map<std::string, std::map<std::string, StoredCheck>> checks;        // bench -> night -> its check
  std::map<std::string, StoredAnchor> anchor;                              // bench -> its newest moved anchor
  // night -> its suite's batch and when the night started: the code each night ran (the replay's baseline code,
  // server/bench_twin.h)
  std::map<std::string, StoredCheck> suites;
};

// A night's "anchor_refit" block (StoredAnchor without its night) and back; errors name the field.
regress::Json StoredAnchorJson(const StoredAnchor& a);
StatusOr<StoredAnchor> StoredAnchorFromJson(const regress::Json& j);

// The night whose valve a baseline was measured on, among one bench's stored checks (night -> check): the last
// night that started before the baseline was made. A baseline summarises runs that had ended when it was saved,
// so a baseline set from a night's batch (`benchctl baseline set --batch`) on the morning after is that night's.
// One set later from an older batch is given the night before it was made: the time is all a baseline records
// of where its runs came from. nullopt when the baseline is older than every stored check or its time is not
// known (0): the bench's first checked night stands for it.
std::optional<std::pair<std::string, StoredCheck>> BaselineNight(const std::map<std::string, StoredCheck>& checks,
                                                                 double baseline_created_unix_s);

// The nights stored before `before_date` ("" = all), the newest 1000.
StatusOr<StoredHealth> LoadStoredHealth(db::Store* store, const std::string& before_date = "");

// One bench's tracking as the API gives it.
valvebench::v1::BenchHealth BenchHealthOf(const std::string& bench, const gap::Tracking& t);

}  // namespace vb::server
