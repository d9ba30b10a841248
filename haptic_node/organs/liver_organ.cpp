#include "organs/liver_organ.h"

#include <string>

#include "liver/liver_setup.h"
#include "mesher/scene_mesh.h"

namespace surgsim {

LiverOrgan::LiverOrgan(const Scene& scene, const std::string& cache_dir, std::ostream* progress) {
  mesh_ = load_scene_mesh(scene, cache_dir, progress);
  surface_ = boundary_surface(mesh_);
  mesh_hash_ = surgsim::mesh_hash(mesh_);
  const LiverTensorSetup setup = liver_tensor_setup(scene.material, scene.fixed, mesh_, cache_dir, scene.file);
  tensors_ = load_liver_tensors(setup, mesh_, scene.material, {"haptic"}, progress, nullptr, scene.file);
  tensor_hash_ = setup.key.combined();
  law_ = std::make_unique<NonlinearLaw>(load_nonlinear_law(scene.nonlinear, scene.material));
  contacts_ = std::make_unique<LiverContacts>(mesh_, surface_, tensors_, scene.tools,
                                              law_->identity() ? nullptr : law_.get());
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
         std::to_string(surface_.nodes.size()) + " surface nodes; ";
}

}  // namespace surgsim
