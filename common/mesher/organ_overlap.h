// Whether the organs of a scene interpenetrate at rest (a scene with an `organs:` list): each organ's rest shape is a
// set of sample points on it and a signed distance (positive outside it), and no sample of one organ may lie deeper
// than a tolerance inside another. An organ placed into another would start the run pushed by it (or, for a rigid
// wall, with an instrument's proxy on the wrong side), so the scene is refused, naming both organs.
#pragma once
#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

#include "mesh/tri_surface.h"
#include "rigid/rigid_surface.h"

namespace surgsim::mesher {

/// One organ at rest.
struct RestShape {
  std::string where;  // names the organ in messages: "FILE:LINE: organ 'NAME' (key 'KEY')"
  std::string name;
  /// Points on the organ (m): the nodes of its boundary, a rigid surface's vertices and triangle centres, or the
  /// centres of a tube's spheres (radius sample_radius).
  std::vector<Eigen::Vector3d> samples;
  double sample_radius = 0;  // m
  /// Its boundary for distance queries (closed organs and rigid surfaces), or null for a tube.
  std::shared_ptr<const rigid::RigidSurface> surface;
  /// A tube: the centre line through the samples in order, radius sample_radius.
  bool tube = false;
  /// A rigid organ: two rigid organs may overlap (a rib set into the wall pushes nothing: neither moves).
  bool rigid = false;
};

/// A closed organ's boundary (a TetMesh's boundary triangles, outward) as a RestShape, and a rigid organ's surface.
RestShape rest_shape_of_surface(const mesh::TriSurface& surface, bool cavity, const std::string& name,
                                const std::string& where);
/// A tube (the intestine's centre line, its radius).
RestShape rest_shape_of_tube(const std::vector<Eigen::Vector3d>& centre_line, double radius, const std::string& name,
                             const std::string& where);

/// Signed distance from `p` to the shape (m, positive outside; the depth inside is its negative). Points behind an
/// open surface but beyond its edge are outside (distance +infinity); points farther than `search` from a surface
/// are outside (+infinity).
double signed_distance(const RestShape& shape, const Eigen::Vector3d& p, double search);

/// The deepest penetration of a sample of `a` into `b` (m, 0 when none), and that sample.
double deepest_penetration(const RestShape& a, const RestShape& b, Eigen::Vector3d* at = nullptr);

/// Throws surgsim::core::Error "<where of a>: organ 'A' lies X mm inside organ 'B' (at [x, y, z]) at rest, more than
/// the T mm allowed (<where of b>) (move them apart: change a placement)" for the first pair that interpenetrates
/// deeper than `tolerance` (m). Pairs of two rigid organs are not checked.
void check_organs_apart(const std::vector<RestShape>& shapes, double tolerance);

}  // namespace surgsim::mesher
