// The helpers on db/records.h's values that are not inline. ClassifyWrite is here, in neither engine, because
// writers of both engines' stores share it; the baseline sources' parsers live in db/prune_plan.cc, beside the
// retention rules that use them.
#include "db/records.h"

namespace vb::db {

WriteFault ClassifyWrite(const Status& st) {
  switch (st.code()) {
    case StatusCode::kOk: return WriteFault::kNone;
    case StatusCode::kUnavailable:
    case StatusCode::kAborted: return WriteFault::kTransient;
    case StatusCode::kFailedPrecondition:
    case StatusCode::kNotFound: return WriteFault::kFenced;
    default: return WriteFault::kPermanent;
  }
}

}  // namespace vb::db
