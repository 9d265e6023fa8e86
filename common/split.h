// A measured run's role in a diagnosis (docs/gap.md): fitted on, held out to judge the fit, or not said. The
// one vocabulary of a dataset manifest's `split`, Run.split, the store's column and the diagnosis; one
// formatter each way. Names: "fit", "holdout", "" (none).
#pragma once

#include <string_view>

#include "common/status.h"

namespace vb {

enum class Split { kNone, kFit, kHoldout };

const char* SplitName(Split split);  // "", "fit", "holdout"
// InvalidArgument "'train' is not fit or holdout" (the caller adds the field) for anything else.
StatusOr<Split> ParseSplit(std::string_view name);

}  // namespace vb
