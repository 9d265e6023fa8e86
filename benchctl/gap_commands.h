// benchctl's sim-to-real gap commands (issue 5): diagnose and identify, locally on a valve-runs/1 dataset.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace vb::client {
class Client;
}

namespace vb::benchctl {

// diagnose DATASET_DIR: the gap of a dataset against a model (a preset name or a model file in ModelSpec
// JSON; default: the dataset's own). json_path: "" = a report for people, "-" = JSON on stdout, else JSON into
// that file (and the report on stdout). emit_model: write the improved model (the model plus the verdict's
// effects and fitted values) as ModelSpec JSON that an emulated bench or --model loads.
int CmdDiagnose(const std::string& dataset_dir, const std::string& model, const std::string& json_path,
                const std::string& emit_model);

// identify DATASET_DIR --params R,mu_r,...: a bounded fit of those nominal parameters; out: the identified
// model as ModelSpec JSON.
int CmdIdentify(const std::string& dataset_dir, const std::string& model, const std::vector<std::string>& params,
                const std::string& out_path, bool json);

// diagnose --runs ID,...: runs stored on the server (imported datasets, or runs of a low-side bench).
// Imported runs keep their t_start_s and split (tags); other runs take t_start_s from their start times
// and the diagnosis makes its own split.
int RemoteDiagnose(client::Client& c, const std::vector<std::int64_t>& run_ids, const std::string& model,
                   const std::string& json_path, const std::string& emit_model);

// import DATASET_DIR: validates the dataset locally, then stores its runs on the server as one batch.
int RemoteImport(client::Client& c, const std::string& dataset_dir, bool json);

}  // namespace vb::benchctl
