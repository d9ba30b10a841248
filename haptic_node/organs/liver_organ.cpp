#include "organs/liver_organ.h"

#include <chrono>
#include <string>

#include "liver/liver_setup.h"
#include "liver/organ_curves.h"
#include "mesher/scene_mesh.h"

namespace surgsim {

LiverOrgan::LiverOrgan(const Scene& scene, const std::string& cache_dir, std::ostream* progress) {
  mesh_ = load_scene_mesh(scene, cache_dir, progress);
  surface_ = boundary_surface(mesh_);
  mesh_hash_ = surgsim::mesh_hash(mesh_);
  const LiverTensorSetup setup = liver_tensor_setup(scene.material, scene.fixed, mesh_, cache_dir, scene.file);
  tensors_ = load_liver_tensors(setup, mesh_, scene.material, {"haptic"}, progress, nullptr, scene.file);
  tensor_hash_ = setup.key.combined();
  law_ = std::make_unique<NonlinearLaw>(
      scene.liver.organ_curves
          ? load_organ_law(mesh_, scene.material, setup.fixed, tensor_hash_, cache_dir, progress)
          : load_nonlinear_law(scene.nonlinear, scene.material));
  contacts_ = std::make_unique<LiverContacts>(mesh_, surface_, tensors_, scene.tools,
                                              law_->identity() ? nullptr : law_.get(), scene.liver.deformation);
  if (scene.liver.deformation == LiverDeformation::kCorotational) {
    // Off the loop thread: the rotations of every surface node at kRotationRefreshHz (the loop keeps its contact
    // nodes' own every tick); absolute deadlines, a late refresh is skipped, not caught up.
    rotation_thread_ = std::thread([this] {
      using Clock = std::chrono::steady_clock;
      const auto period = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1 / kRotationRefreshHz));
      auto next = Clock::now();
      while (!stop_rotations_.load(std::memory_order_relaxed)) {
        contacts_->refresh_rotations();
        next += period;
        const auto now = Clock::now();
        if (next < now) next = now;
        std::this_thread::sleep_until(next);
      }
    });
  }
}

LiverOrgan::~LiverOrgan() {
  stop_rotations_.store(true);
  if (rotation_thread_.joinable()) rotation_thread_.join();
}

void LiverOrgan::step(const InstrumentInput* inputs, int count, double dt, ContactTick* out) noexcept {
  // An instrument whose input is lost drops its own contacts and gets zero force; the others are solved as usual.
  contacts_->step(inputs, count, out, dt);
}

ContactEntry LiverOrgan::contact_entry(int l) const noexcept {
  const ContactSolution& s = contacts_->solution();
  ContactEntry e;
  e.node = s.nodes[static_cast<std::size_t>(l)];
  e.instrument = contacts_->node_instrument(l);
  e.lambda = s.lambda[static_cast<std::size_t>(l)];
  e.u_tilde = contacts_->corrected(l);
  return e;
}

std::string LiverOrgan::describe() const {
  return std::to_string(mesh_.nodes.rows()) + " nodes, " + std::to_string(mesh_.tets.rows()) + " tets, " +
         std::to_string(surface_.nodes.size()) + " surface nodes; " + to_string(contacts_->deformation()) + "; ";
}

}  // namespace surgsim
