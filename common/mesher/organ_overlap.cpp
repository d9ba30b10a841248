#include "mesher/organ_overlap.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "core/error.h"

namespace surgsim::mesher {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// Distance from p to the segment [a, b].
double segment_distance(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  const Eigen::Vector3d ab = b - a;
  const double len2 = ab.squaredNorm();
  const double t = len2 > 0 ? std::clamp((p - a).dot(ab) / len2, 0.0, 1.0) : 0.0;
  return (a + t * ab - p).norm();
}

}  // namespace

RestShape rest_shape_of_surface(const mesh::TriSurface& surface, bool cavity, const std::string& name,
                                const std::string& where) {
  RestShape s;
  s.name = name;
  s.where = where;
  s.surface = std::make_shared<const rigid::RigidSurface>(surface, cavity, where);
  s.samples.reserve(static_cast<std::size_t>(surface.vertices.rows() + surface.tris.rows()));
  for (Eigen::Index v = 0; v < surface.vertices.rows(); ++v) s.samples.emplace_back(surface.vertices.row(v));
  for (Eigen::Index t = 0; t < surface.tris.rows(); ++t) {
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (int k = 0; k < 3; ++k) c += surface.vertices.row(surface.tris(t, k)).transpose();
    s.samples.push_back(c / 3);
  }
  return s;
}

RestShape rest_shape_of_tube(const std::vector<Eigen::Vector3d>& centre_line, double radius, const std::string& name,
                             const std::string& where) {
  RestShape s;
  s.name = name;
  s.where = where;
  s.samples = centre_line;
  s.sample_radius = radius;
  s.tube = true;
  return s;
}

double signed_distance(const RestShape& shape, const Eigen::Vector3d& p, double search) {
  if (shape.tube) {
    double d = kInf;
    for (std::size_t i = 0; i + 1 < shape.samples.size(); ++i) {
      d = std::min(d, segment_distance(p, shape.samples[i], shape.samples[i + 1]));
    }
    if (shape.samples.size() == 1) d = (p - shape.samples[0]).norm();
    return d - shape.sample_radius;
  }
  if (!shape.surface) return kInf;
  const rigid::ClosestPoint c = shape.surface->closest_point(p, search);
  if (!c.found) return kInf;
  if (c.distance >= 0) return c.distance;
  // Behind the surface: count it only where p lies under the surface, i.e. p projects into the closest triangle (p
  // is then along that triangle's normal from its closest point, within 1 um), not beside the edge of an open
  // surface, where "behind" means nothing. Inside a closed surface the nearest point is on a face: counted. Behind a
  // convex vertex of a cavity, where p projects into no face, a sample near it is (the faces around).
  const Eigen::Vector3d d = p - c.point;
  const Eigen::Vector3d& n = shape.surface->face_normal(c.triangle);
  if ((d - d.dot(n) * n).norm() > 1e-6) return kInf;
  return c.distance;
}

double deepest_penetration(const RestShape& a, const RestShape& b, Eigen::Vector3d* at) {
  double deepest = 0;
  const double search = 0.05 + a.sample_radius;  // m: deeper overlaps are found from nearer samples
  for (const Eigen::Vector3d& p : a.samples) {
    const double sd = signed_distance(b, p, search);
    const double depth = a.sample_radius - sd;  // a sphere of sample_radius about p overlaps b by this much
    if (std::isfinite(depth) && depth > deepest) {
      deepest = depth;
      if (at != nullptr) *at = p;
    }
  }
  return deepest;
}

void check_organs_apart(const std::vector<RestShape>& shapes, double tolerance) {
  for (std::size_t i = 0; i < shapes.size(); ++i) {
    for (std::size_t j = 0; j < shapes.size(); ++j) {
      if (i == j || (shapes[i].rigid && shapes[j].rigid)) continue;
      Eigen::Vector3d at = Eigen::Vector3d::Zero();
      const double depth = deepest_penetration(shapes[i], shapes[j], &at);
      if (depth > tolerance) {
        std::ostringstream os;
        os.precision(3);
        os << shapes[i].where << ": organ '" << shapes[i].name << "' lies " << 1e3 * depth << " mm inside organ '"
           << shapes[j].name << "' (at [" << at.x() << ", " << at.y() << ", " << at.z() << "] m) at rest, more than the "
           << 1e3 * tolerance << " mm allowed (" << shapes[j].where
           << ") (move them apart: change a placement or a size)";
        throw core::Error(os.str());
      }
    }
  }
}

}  // namespace surgsim::mesher
