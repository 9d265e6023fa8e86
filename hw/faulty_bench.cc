#include "hw/faulty_bench.h"

#include <chrono>
#include <limits>
#include <thread>

namespace vb::hw {

void FaultyBench::Offset::OnSample(const BenchSample& s) {
  if (next == nullptr) return;
  BenchSample out = s;
  if (Due(self->f_.current_offset_from_s, s.t_s)) out.i_A += self->f_.current_offset_A;
  next->OnSample(out);
}

Status FaultyBench::Start(SampleSink* sink) {
  t_s_ = 0.0;
  stalled_ = false;
  last_fresh_ = Measurement{};
  offset_.self = this;
  offset_.next = sink;
  return inner_->Start(&offset_);
}

Status FaultyBench::Apply(const SwitchCommand& command) {
  if (Due(f_.apply_error_at_s, t_s_)) return f_.error;
  return inner_->Apply(command);
}

Status FaultyBench::AdvanceTo(double t_s, Measurement* m) {
  if (Due(f_.error_at_s, t_s)) return f_.error;
  if (Due(f_.stall_at_s, t_s) && !stalled_) {
    stalled_ = true;
    std::this_thread::sleep_for(std::chrono::duration<double>(f_.stall_wall_s));
  }
  Measurement fresh;
  VB_RETURN_IF_ERROR(inner_->AdvanceTo(t_s, &fresh));
  t_s_ = t_s;
  if (Due(f_.current_offset_from_s, t_s)) fresh.current_A += f_.current_offset_A;
  if (Due(f_.nan_at_s, t_s)) fresh.current_A = std::numeric_limits<double>::quiet_NaN();
  if (Due(f_.stale_from_s, t_s)) {
    if (m != nullptr) *m = last_fresh_;
    return Status::Ok();
  }
  last_fresh_ = fresh;
  if (m != nullptr) *m = fresh;
  return Status::Ok();
}

}  // namespace vb::hw
