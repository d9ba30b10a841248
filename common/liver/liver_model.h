// A liver's model apart from its state (MuJoCo's mjModel / mjData; Jolt's SoftBodySharedSettings /
// SoftBodyMotionProperties). The model is what every tick reads and none writes: the mesh, its surface, the fixed set,
// the precomputed compliance, the force law, their hashes and a topology generation. It is built off the loop (it may
// precompute) and shared, immutable, by every instance built on it. An instance is one liver in a scene: the contact
// state and scratch bound to a model (contact::ToolContacts), which it keeps alive. A change of topology (a cut) is a
// new model with the next generation, and a new instance swapped in between two ticks (haptic_node's LiverOrgan).
#pragma once
#include <cstdint>
#include <iosfwd>
#include <memory>
#include <string>
#include <vector>

#include "compliance/corotation.h"
#include "compliance/precompute.h"
#include "contact/tool_contacts.h"
#include "fem/fixed_set.h"
#include "fem/material.h"
#include "mesh/mesh.h"
#include "nonlinear/nonlinear_law.h"
#include "tool/tool.h"

namespace surgsim::liver {

/// The immutable, shareable part of a liver.
struct LiverModel {
  mesh::TetMesh mesh;
  mesh::SurfaceMesh surface;  // boundary of mesh
  fem::Material material;
  fem::FixedSet fixed;          // resolved on mesh
  compliance::Tensors tensors;  // the "haptic" block (surface x surface)
  nonlinear::NonlinearLaw law;  // identity without curves
  std::uint64_t mesh_hash = 0;
  std::uint64_t tensor_hash = 0;  // the tensor cache key (mesh, material, fixed set, rows)
  std::uint64_t generation = 0;   // topology generation: 0 for the scene's mesh, +1 per change of topology
};

/// What a model is built from (the liver part of a scene; scene/ sits above this folder).
struct LiverModelSource {
  fem::Material material;
  fem::FixedRegion fixed;
  nonlinear::NonlinearSpec nonlinear;  // the quasi non-linear law's curves (scene key nonlinear)
  bool organ_curves = false;           // liver.organ_curves: the law from the organ's own curves instead
  std::string where;                   // the scene file, for errors
};

/// Builds a model on `mesh` (allocates; loads the tensors from `cache_dir` or precomputes them, with progress on
/// `progress`). Throws surgsim::core::Error naming source.where.
std::shared_ptr<const LiverModel> build_liver_model(mesh::TetMesh mesh, const LiverModelSource& source,
                                                    const std::string& cache_dir, std::ostream* progress,
                                                    std::uint64_t generation = 0);

/// One liver's state: the contact model bound to a model, which it keeps alive. Built off the loop (allocates);
/// its step allocates nothing.
class LiverInstance {
 public:
  LiverInstance(std::shared_ptr<const LiverModel> model, const std::vector<tool::ToolSpec>& tools,
                compliance::LiverDeformation deformation);
  const LiverModel& model() const { return *model_; }
  const std::shared_ptr<const LiverModel>& shared_model() const { return model_; }
  contact::ToolContacts& contacts() { return *contacts_; }
  const contact::ToolContacts& contacts() const { return *contacts_; }

 private:
  std::shared_ptr<const LiverModel> model_;
  std::unique_ptr<contact::ToolContacts> contacts_;
};

}  // namespace surgsim::liver
