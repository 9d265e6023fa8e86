// HDF5 writer (libhdf5, C API): the layout is in run_file.h.
#include <hdf5.h>

#include <algorithm>

#include "export/run_file.h"

namespace vb::exportfile {
namespace {

// One HDF5 identifier, closed with its own close function.
class Hid {
 public:
  Hid(hid_t id, herr_t (*close)(hid_t)) : id_(id), close_(close) {}
  ~Hid() {
    if (id_ >= 0) close_(id_);
  }
  Hid(const Hid&) = delete;
  Hid& operator=(const Hid&) = delete;
  hid_t get() const { return id_; }
  bool ok() const { return id_ >= 0; }

 private:
  hid_t id_;
  herr_t (*close_)(hid_t);
};

// A variable-length UTF-8 string type (h5py reads it as str).
hid_t VarString() {
  const hid_t t = H5Tcopy(H5T_C_S1);
  H5Tset_size(t, H5T_VARIABLE);
  H5Tset_cset(t, H5T_CSET_UTF8);
  return t;
}

bool StringAttr(hid_t obj, const char* name, const std::string& value) {
  Hid type(VarString(), H5Tclose);
  Hid space(H5Screate(H5S_SCALAR), H5Sclose);
  Hid a(H5Acreate2(obj, name, type.get(), space.get(), H5P_DEFAULT, H5P_DEFAULT), H5Aclose);
  const char* p = value.c_str();
  return a.ok() && H5Awrite(a.get(), type.get(), &p) >= 0;
}

template <typename T>
bool NumberAttr(hid_t obj, const char* name, hid_t file_type, hid_t mem_type, T value) {
  Hid space(H5Screate(H5S_SCALAR), H5Sclose);
  Hid a(H5Acreate2(obj, name, file_type, space.get(), H5P_DEFAULT, H5P_DEFAULT), H5Aclose);
  return a.ok() && H5Awrite(a.get(), mem_type, &value) >= 0;
}

bool Scalars(hid_t file, const char* group, const std::vector<Value>& values) {
  Hid g(H5Gcreate2(file, group, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Gclose);
  if (!g.ok()) return false;
  for (const auto& v : values) {
    Hid space(H5Screate(H5S_SCALAR), H5Sclose);
    Hid d(H5Dcreate2(g.get(), v.name.c_str(), H5T_IEEE_F64LE, space.get(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
          H5Dclose);
    if (!d.ok() || H5Dwrite(d.get(), H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, &v.value) < 0) return false;
    if (!StringAttr(d.get(), "units", v.unit)) return false;
  }
  return true;
}

bool Channels(hid_t file, const std::vector<Channel>& channels) {
  Hid g(H5Gcreate2(file, "channels", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Gclose);
  if (!g.ok()) return false;
  constexpr hsize_t kChunk = 65536;
  for (const auto& c : channels) {
    const hsize_t n = c.values.size();
    Hid space(H5Screate_simple(1, &n, nullptr), H5Sclose);
    Hid props(H5Pcreate(H5P_DATASET_CREATE), H5Pclose);
    if (n > kChunk) {
      H5Pset_chunk(props.get(), 1, &kChunk);
      if (H5Zfilter_avail(H5Z_FILTER_DEFLATE) > 0) {
        H5Pset_shuffle(props.get());
        H5Pset_deflate(props.get(), 4);
      }
    }
    Hid d(H5Dcreate2(g.get(), c.name.c_str(), H5T_IEEE_F64LE, space.get(), H5P_DEFAULT, props.get(), H5P_DEFAULT),
          H5Dclose);
    if (!d.ok()) return false;
    if (n > 0 && H5Dwrite(d.get(), H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, c.values.data()) < 0) return false;
    if (!StringAttr(d.get(), "units", c.unit)) return false;
  }
  return true;
}

}  // namespace

Status WriteHdf5(const RunFile& run, const std::string& path) {
  if (auto st = Validate(run); !st.ok()) return st;
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);  // errors come back as our Status, not printed stacks
  Hid file(H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT), H5Fclose);
  if (!file.ok()) return Status::Unavailable(path + ": cannot create the HDF5 file");
  const hid_t f = file.get();
  const bool ok = StringAttr(f, "format", "valvebench-run/1") &&
                  NumberAttr<std::int64_t>(f, "run_id", H5T_STD_I64LE, H5T_NATIVE_INT64, run.run_id) &&
                  StringAttr(f, "name", run.name) && StringAttr(f, "controller", run.controller) &&
                  StringAttr(f, "bench", run.bench) && StringAttr(f, "status", run.status) &&
                  StringAttr(f, "reason", run.reason) && StringAttr(f, "spec_json", run.spec_json) &&
                  NumberAttr<double>(f, "t0_s", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, run.t0_s) &&
                  NumberAttr<double>(f, "sample_period_s", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, run.sample_period_s) &&
                  Channels(f, run.channels) && Scalars(f, "conditions", run.conditions) &&
                  Scalars(f, "metrics", run.metrics);
  if (!ok) return Status::Unavailable(path + ": HDF5 write failed");
  if (H5Fflush(f, H5F_SCOPE_GLOBAL) < 0) return Status::Unavailable(path + ": HDF5 flush failed");
  return Status::Ok();
}

}  // namespace vb::exportfile
