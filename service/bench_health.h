// The bench twin's stored history (docs/track.md "On the server"): each bench's nightly identified values, as
// the nights scheduler keeps them in each night's record (regressions table, result JSON "health"), read back
// for the next night's tracking (server/nights.cc) and for GetBenchHealth.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <utility>

#include "common/status.h"
#include "db/store.h"
#include "gap/track.h"
#include "valvebench/v1/api.pb.h"

namespace vb::server {

struct StoredHealth {
  std::map<std::string, std::map<std::string, gap::SessionValues>> values;  // bench -> night -> values
  std::map<std::string, std::pair<std::string, std::int64_t>> first_check;  // bench -> (night, batch)
};

// The nights stored before `before_date` ("" = all), the newest 1000.
StatusOr<StoredHealth> LoadStoredHealth(db::Store* store, const std::string& before_date = "");

// One bench's tracking as the API gives it.
valvebench::v1::BenchHealth BenchHealthOf(const std::string& bench, const gap::Tracking& t);

}  // namespace vb::server
