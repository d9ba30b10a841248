#include "liver/liver_setup.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <ostream>

#include "core/error.h"
#include "fem/fem.h"

using namespace surgsim::core;
using namespace surgsim::mesh;
using namespace surgsim::fem;
using namespace surgsim::compliance;

namespace surgsim::liver {

namespace {

// Exclusive advisory lock on <path>.lock for the lifetime of the object.
class FileLock {
 public:
  explicit FileLock(const std::string& path) {
    fd_ = ::open((path + ".lock").c_str(), O_CREAT | O_RDWR | O_CLOEXEC, 0644);
    if (fd_ >= 0 && ::flock(fd_, LOCK_EX) != 0) {
      ::close(fd_);
      fd_ = -1;
    }
  }
  ~FileLock() {
    if (fd_ >= 0) {
      ::flock(fd_, LOCK_UN);
      ::close(fd_);
    }
  }
  FileLock(const FileLock&) = delete;
  FileLock& operator=(const FileLock&) = delete;

 private:
  int fd_ = -1;
};

void keep_blocks(Tensors& t, const std::vector<std::string>& blocks) {
  if (blocks.empty()) return;
  t.blocks.erase(std::remove_if(t.blocks.begin(), t.blocks.end(),
                                [&](const TensorBlock& b) {
                                  return std::find(blocks.begin(), blocks.end(), b.name) == blocks.end();
                                }),
                 t.blocks.end());
}

}  // namespace

Precision scene_precision(std::size_t double_bytes, std::size_t float_above_mib) {
  return double_bytes > (float_above_mib << 20) ? Precision::kFloat : Precision::kDouble;
}

PrecomputeOptions scene_precompute_options(int contact_count, const std::vector<RowSet>& rows) {
  // The haptic block (contacts x contacts) is stored as one half; the precision from its size in double.
  PrecomputeOptions o;
  o.symmetric_blocks = {"haptic"};
  o.precision = Precision::kDouble;
  o.precision = scene_precision(estimate_tensor_bytes(contact_count, rows, o));
  return o;
}

LiverTensorSetup liver_tensor_setup(const Material& material, const FixedRegion& fixed, const TetMesh& mesh,
                                    const std::string& cache_dir, const std::string& where) {
  LiverTensorSetup s;
  // A material region holding no element is refused here too: a cached tensor file is loaded without assembling.
  element_materials(mesh, material, where);
  s.fixed = fixed_set_from_region(mesh, fixed);
  s.contacts = contactable_nodes(mesh, s.fixed);
  if (s.contacts.empty()) throw_error(where, ": key 'fixed': every surface node is fixed; nothing can be touched");
  s.rows = standard_row_sets(mesh, s.fixed, s.contacts);
  s.options = scene_precompute_options(static_cast<int>(s.contacts.size()), s.rows);
  s.key = tensor_cache_key(mesh, material, s.fixed, s.contacts, s.rows, s.options);
  char name[64];
  std::snprintf(name, sizeof name, "/tensors-%016llx.bin", static_cast<unsigned long long>(s.key.combined()));
  s.cache_path = cache_dir + name;
  return s;
}

Tensors load_liver_tensors(const LiverTensorSetup& setup, const TetMesh& mesh, const Material& material,
                           const std::vector<std::string>& blocks, std::ostream* log, CacheOutcome* outcome,
                           const std::string& where) {
  CacheOutcome local;
  CacheOutcome& out = outcome != nullptr ? *outcome : local;
  Tensors t;
  out.load = load_tensor_cache(setup.cache_path, setup.key, t, blocks);
  if (out.load.status == CacheStatus::kOk) {
    t.material = material;  // part of the key
    return t;
  }

  // Serialize builders: whoever gets the lock second finds the cache written by the first.
  FileLock lock(setup.cache_path);
  out.load = load_tensor_cache(setup.cache_path, setup.key, t, blocks);
  if (out.load.status == CacheStatus::kOk) {
    t.material = material;  // part of the key
    return t;
  }
  if (log != nullptr && out.load.status != CacheStatus::kMissing) {
    *log << "tensors: cache " << setup.cache_path << " is " << to_string(out.load.status) << " (" << out.load.detail
         << "); rebuilding it (nothing to do by hand; a file that keeps failing can be deleted)\n";
  }

  // Errors name the scene and its mesh file (the rigid-mode diagnosis before factoring, and CHOLMOD's failures).
  const std::string mesh_file = mesh.source.empty() || mesh.source == where ? "" : " (mesh " + mesh.source + ")";
  const std::string named = where.empty() ? (mesh.source.empty() ? "" : "mesh " + mesh.source) : where + mesh_file;
  const ElasticModel model = build_elastic_model(mesh, material, setup.fixed, named);
  PrecomputeOptions options = setup.options;
  double last_print = -1;
  if (log != nullptr) {
    options.progress = [log, &last_print](const PrecomputeProgress& p) {
      if (p.elapsed_s - last_print < 0.5 && p.fraction < 1.0) return;
      last_print = p.elapsed_s;
      *log << "tensors: " << static_cast<int>(100 * p.fraction) << " % (" << p.columns_done << "/" << p.columns_total
           << " columns), " << p.elapsed_s << " s elapsed, ETA " << p.eta_s << " s\n";
    };
  }
  PrecomputeReport report;
  try {
    t = precompute_tensors(model, setup.contacts, setup.rows, options, &report);
  } catch (const Error& e) {  // e.g. CHOLMOD
    if (named.empty()) throw;
    throw Error(named + ": " + e.what());
  }
  out.rebuilt = true;
  try {
    save_tensor_cache(setup.cache_path, t, setup.key);
    out.saved = true;
  } catch (const Error& e) {
    out.save_error = e.what();
    if (log != nullptr) *log << "tensors: " << e.what() << " (continuing without a cache)\n";
  }
  if (log != nullptr) {
    *log << "tensors: " << setup.contacts.size() << " contactable nodes, precomputed in " << report.total_s
         << " s on " << report.threads << " thread(s), " << to_string(setup.options.precision) << " ("
         << report.memory.describe() << ")" << (out.saved ? ", cached in " + setup.cache_path : "") << "\n";
  }
  keep_blocks(t, blocks);
  return t;
}

}  // namespace surgsim::liver
