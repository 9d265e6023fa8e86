// benchctl export RUN --hdf5 FILE / --mat FILE: a stored run with units, spec and conditions (export/).
#pragma once

#include <cstdint>
#include <string>

#include "client/client.h"

namespace vb::benchctl {

// Writes the files that are named (empty path: not written; at least one): CSV through RemoteExport, HDF5 and
// MAT from the run and its trace.
int RemoteExportFiles(client::Client& c, std::int64_t run_id, const std::string& csv_path, const std::string& hdf5_path,
                      const std::string& mat_path);

}  // namespace vb::benchctl
