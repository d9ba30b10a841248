// The haptic tick applies the organ law's surface field (nonlinear/nonlinear_law.h, fitted by nonlinear/organ_curves.h)
// at each instrument's own contact nodes (common/contact/tool_contacts.cpp, ToolContacts::finish), without allocating.
#include <gtest/gtest.h>

#include "fem/fixed_set.h"
#include "nonlinear/nonlinear_law.h"
#include "nonlinear/organ_curves.h"
#include "contact/tool_contacts.h"
#include "support/alloc_counter.h"
#include "support/slab_util.h"

using namespace surgsim::tool;
using namespace surgsim::fem;
using namespace surgsim::compliance;
using namespace surgsim::nonlinear;
using namespace surgsim::contact;

namespace surgsim {
namespace {

TEST(ToolContactsOrganLaw, TheTickScalesThePushByTheFieldAtItsContactNodes) {
  const test::Slab slab(8, 8, 2, {0.2, 0.2, 0.04});
  FixedRegion region;  // the slab's own clamp (tests/support/slab_util.h)
  region.has_plane = true;
  region.plane_point = {0, 0, 0.001};
  region.plane_normal = {0, 0, -1};
  const FixedSet fixed = fixed_set_from_region(slab.mesh, region);
  // ratio = 1 + 2 e, e = depth / thickness (no fit sites: residual 1).
  SurfaceForceField field;
  field.degree = 1;
  field.a[1] = 2.0;
  field.e_max = 1.0;
  OrganSurfaceGeometry g = organ_surface_geometry(slab.mesh, fixed);
  field.thickness = g.thickness;
  field.lever = g.lever;
  field.normal = g.normal;
  for (Eigen::Index n = 0; n < slab.mesh.nodes.rows(); ++n)
    field.position.push_back(slab.mesh.nodes.row(n).transpose());
  const NonlinearLaw law(std::nullopt, std::nullopt, field);

  ToolSpec spec;
  spec.trocar = {0.1031, 0.0977, 0.2};
  spec.axis = {0, 0, -1};
  spec.shaft_points = 1;
  spec.force_limit = 100.0;
  spec.contact_capacity = 20;
  ToolContacts linear(slab.mesh, slab.surface, slab.tensors, spec),
      organ(slab.mesh, slab.surface, slab.tensors, spec, &law);
  long allocations = 0;
  int checked = 0;
  for (int k = 0; k <= 40; ++k) {
    const double depth = 0.00015 * k - 0.0005;
    const ToolGeometry tool = test::vertical_tool({0.1031, 0.0977, 0.04 - depth});
    ContactTick lin, org;
    linear.step(tool, 0.5, lin);
    {
      test::AllocationCounter counter;
      organ.step(tool, 0.5, org);
      allocations += counter.count();
    }
    const ContactSolution& s = organ.solution();
    if (s.count == 0) {
      EXPECT_EQ(org.force, lin.force);
      continue;
    }
    const Eigen::Vector3d d = org.direction;
    double delta = 0;
    for (int l = 0; l < s.count; ++l) delta += s.displacement[static_cast<std::size_t>(l)].dot(d);
    delta = std::abs(delta / s.count);
    const double ratio = field.ratio(s.nodes.data(), s.count, d, delta);
    EXPECT_GT(ratio, 1.0) << depth;  // a push on the top: the field applies
    EXPECT_NEAR(org.force.dot(d), ratio * lin.force.dot(d), 1e-12 * lin.force.norm()) << depth;
    EXPECT_LT((org.force - org.force.dot(d) * d - (lin.force - lin.force.dot(d) * d)).norm(), 1e-12 * lin.force.norm());
    ++checked;
  }
  EXPECT_GT(checked, 30);
  EXPECT_EQ(allocations, 0);
}

}  // namespace
}  // namespace surgsim
