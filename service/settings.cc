#include "service/settings.h"

namespace vb::server {

runs::Policy ServiceSettings::AdmitPolicy() const {
  runs::Policy p;
  p.benches = benches;
  if (admit_limits) {
    p.limits = *admit_limits;
    return p;
  }
  p.limits.max_spec_bytes = limits.max_spec_bytes();
  p.limits.max_duration_s = limits.max_duration_s();
  p.limits.max_record_rate_Hz = limits.max_record_rate_hz();
  p.limits.max_queued_runs_per_user = limits.max_queued_runs_per_user();
  p.limits.max_runs_per_submission = limits.max_runs_per_submission();
  p.limits.max_trace_bytes_per_run = limits.max_trace_mb_per_run() * 1e6;
  if (limits.max_disk_mb_per_user() > 0.0) p.limits.max_disk_bytes_per_user = limits.max_disk_mb_per_user() * 1e6;
  p.benches = benches;
  return p;
}

}  // namespace vb::server
