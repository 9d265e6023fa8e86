#include "proto/api_convert.h"

namespace vb::api {

valvebench::v1::RunKey ToProto(const RunKey& key) {
  valvebench::v1::RunKey out;
  out.set_name(key.name);
  for (const auto& c : key.sweep) {
    auto* p = out.add_sweep();
    p->set_field(c.field);
    p->set_value(c.value);
  }
  out.set_repeat(key.repeat);
  return out;
}

RunKey FromProto(const valvebench::v1::RunKey& key) {
  RunKey out{key.name(), {}, key.repeat()};
  for (const auto& c : key.sweep()) out.sweep.push_back({c.field(), c.value()});
  return out;
}

}  // namespace vb::api
