#include "liver/liver_model.h"

#include <utility>

#include "liver/liver_setup.h"
#include "nonlinear/organ_curves.h"

namespace surgsim::liver {

std::shared_ptr<const LiverModel> build_liver_model(mesh::TetMesh mesh, const LiverModelSource& source,
                                                    const std::string& cache_dir, std::ostream* progress,
                                                    std::uint64_t generation) {
  auto m = std::make_shared<LiverModel>();
  m->mesh = std::move(mesh);
  m->surface = mesh::boundary_surface(m->mesh);
  m->material = source.material;
  m->mesh_hash = mesh::mesh_hash(m->mesh);
  const LiverTensorSetup setup = liver_tensor_setup(source.material, source.fixed, m->mesh, cache_dir, source.where);
  m->fixed = setup.fixed;
  m->tensors = load_liver_tensors(setup, m->mesh, source.material, {"haptic"}, progress, nullptr, source.where);
  m->tensor_hash = setup.key.combined();
  m->law = source.organ_curves
               ? nonlinear::load_organ_law(m->mesh, source.material, setup.fixed, m->tensor_hash, cache_dir, progress)
               : nonlinear::load_nonlinear_law(source.nonlinear, source.material);
  m->generation = generation;
  return m;
}

LiverInstance::LiverInstance(std::shared_ptr<const LiverModel> model, const std::vector<tool::ToolSpec>& tools,
                             compliance::LiverDeformation deformation)
    : model_(std::move(model)) {
  const LiverModel& m = *model_;
  contacts_ = std::make_unique<contact::ToolContacts>(m.mesh, m.surface, m.tensors, tools,
                                                      m.law.identity() ? nullptr : &m.law, deformation);
}

}  // namespace surgsim::liver
