#include "hw/device_bench.h"

#include <algorithm>

#include "common/format.h"

namespace vb::hw {

BenchSample CurrentOnlySample(double t_s, std::int8_t gate, double i_A) {
  BenchSample b;
  b.t_s = t_s;
  b.gate = gate;
  b.v_coil_V = kNotMeasured;
  b.i_A = i_A;
  b.x_m = b.v_mps = kNotMeasured;
  b.v2_integral_V2s = b.energy_J = b.switches = b.gate_on_s = kNotMeasured;
  return b;
}

void FillCurrentOnlyMeasurement(double t_s, double i_A, double supply_V, Measurement* m) {
  m->t_s = t_s;
  m->current_A = i_A;
  m->position_m = m->velocity_mps = kNotMeasured;
  m->supply_V = supply_V;
}

Status Reconnect(Transport& transport, int attempts, const std::function<Status()>& identify,
                 const std::string& bench) {
  Status st = Status::Unavailable("not reopened");
  for (int k = 0; k < std::max(1, attempts) && !st.ok(); ++k) {
    st = transport.Reopen();
    if (st.ok()) st = identify();
  }
  return st.ok() ? st : st.WithContext("bench " + bench + ": reconnect");
}

Status CheckSupply(double supply_V, double max_supply_V, const std::string& bench) {
  if (supply_V > 0.0 && supply_V <= max_supply_V) return Status::Ok();
  return Status::FailedPrecondition("supply_V: " + FormatNumber(supply_V) + " V is outside (0, " +
                                    FormatNumber(max_supply_V) + "] for bench " + bench);
}

}  // namespace vb::hw
