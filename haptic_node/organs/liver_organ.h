// The liver in the haptic node (Cotin 1998, DESIGN.md 4.1-4.2): the scene's tetrahedral mesh, the "haptic" block of
// the precomputed tensors (from the cache both nodes share), the quasi non-linear law and the contact model
// (LiverContacts: bucket grid, unilateral contacts and grasps, mutual-influence correction, device clamp).
#pragma once
#include <atomic>
#include <memory>
#include <thread>

#include "liver/nonlinear_law.h"
#include "liver/precompute.h"
#include "mesh/mesh.h"
#include "organ.h"
#include "organs/liver_contacts.h"

namespace surgsim {

class LiverOrgan final : public HapticOrgan {
 public:
  /// Init (allocates; may precompute the tensors, with progress on `progress`). Throws surgsim::Error.
  LiverOrgan(const Scene& scene, const std::string& cache_dir, std::ostream* progress);
  /// Stops the rotation thread (corotational).
  ~LiverOrgan() override;
  LiverOrgan(const LiverOrgan&) = delete;
  LiverOrgan& operator=(const LiverOrgan&) = delete;

  const char* model_name() const override { return "liver"; }
  using HapticOrgan::step;
  void step(const InstrumentInput* inputs, int count, double dt, ContactTick* out) noexcept override;
  int contacts() const noexcept override { return contacts_->solution().count; }
  int instrument_contacts(int i) const noexcept override { return contacts_->instrument_nodes(i); }
  int contact_entries() const noexcept override { return contacts_->solution().count; }
  ContactEntry contact_entry(int l) const noexcept override;
  std::uint64_t mesh_hash() const override { return mesh_hash_; }
  std::uint64_t tensor_hash() const override { return tensor_hash_; }
  std::uint32_t node_count() const override { return static_cast<std::uint32_t>(mesh_.nodes.rows()); }
  std::uint32_t surface_node_count() const override { return static_cast<std::uint32_t>(surface_.nodes.size()); }
  bool nonlinear_law() const override { return !law_->identity(); }
  std::string describe() const override;

  const TetMesh& mesh() const { return mesh_; }
  const LiverContacts& liver_contacts() const { return *contacts_; }

 private:
  TetMesh mesh_;
  SurfaceMesh surface_;
  std::uint64_t mesh_hash_ = 0;
  Tensors tensors_;                        // "haptic" block only
  std::uint64_t tensor_hash_ = 0;
  std::unique_ptr<NonlinearLaw> law_;      // identity when the scene has no curves
  std::unique_ptr<LiverContacts> contacts_;
  // Corotational (issue 16): every surface node's rotation refreshed off the loop thread.
  static constexpr double kRotationRefreshHz = 200;
  std::atomic<bool> stop_rotations_{false};
  std::thread rotation_thread_;
};

}  // namespace surgsim
