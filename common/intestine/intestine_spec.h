// The intestine's own scene type (Raghupathi 2004, docs/DESIGN.md, section 'Intestine: mass-spring + stochastic
// collisions'). Read from YAML by scene/.
#pragma once
#include <Eigen/Core>
#include <string>
#include <utility>
#include <vector>

#include "intestine/intestine_model.h"

namespace surgsim::intestine {

/// The intestine's body (model "intestine"; Raghupathi et al. 2004, docs/DESIGN.md, section 'Intestine: mass-spring +
/// stochastic collisions'), YAML `intestine: {...}`.
/// Every key is optional and defaults to intestine::IntestineParams (the paper's 4 m intestine on 4 x 100 masses):
///   rest shape: length, cylinder_radius, folds, angular_span, fold_shape, axis_origin, axis_direction, columns, rows
///     (rows x columns <= 2048, the BodyState bound), intestine_radius, mesentery_thickness;
///   masses and springs: intestine_node_mass, mesentery_node_mass, structural_stiffness, shear_stiffness,
///     bending_stiffness, spring_damping, drag, gravity, integrator (implicit_euler | symplectic_euler);
///   probe (a sphere at each instrument's tool tip): probe_radius, probe_stiffness; each probe's force is clamped to
///     its own instrument's force_limit;
///   collisions: self_collisions, random_pairs (the paper's n), random_mesentery_pairs, seed, response_iterations,
///     contact_capacity.
struct IntestineSpec {
  IntestineParams params;             // ready for IntestineModel: probe_force_limit = tools[0].force_limit
  double probe_radius = 0.01;         // m
};

}  // namespace surgsim::intestine
