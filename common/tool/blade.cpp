#include "tool/blade.h"

#include <cmath>

namespace surgsim::tool {

namespace {
constexpr double kMinArea = 1e-12;  // m^2: a triangle smaller than this is left out

bool finite(const ToolGeometry& g) {
  return g.tip.allFinite() && g.jaw_tips[0].allFinite() && g.jaw_tips[1].allFinite();
}

void add(BladeSweep& s, const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  BladeTriangle t{{a, b, c}};
  if (t.area() < kMinArea) return;
  s.triangles[static_cast<std::size_t>(s.count++)] = t;
}
}  // namespace

double BladeTriangle::area() const { return 0.5 * (p[1] - p[0]).cross(p[2] - p[0]).norm(); }

double BladeSweep::area() const {
  double a = 0;
  for (int i = 0; i < count; ++i) a += triangles[static_cast<std::size_t>(i)].area();
  return a;
}

BladeSweep blade_sweep(const ToolGeometry& before, double jaw_before, const ToolGeometry& after, double jaw_after) {
  BladeSweep s;
  if (!(std::isfinite(jaw_before) && std::isfinite(jaw_after)) || !(jaw_after < jaw_before)) return s;
  if (!finite(before) || !finite(after)) return s;
  for (int b = 0; b < 2; ++b) {
    const Eigen::Vector3d& from = before.jaw_tips[static_cast<std::size_t>(b)];
    const Eigen::Vector3d& to = after.jaw_tips[static_cast<std::size_t>(b)];
    add(s, before.tip, from,
        to);  // the quadrilateral (pivot, tip before, tip after, pivot after) split on its diagonal
    add(s, before.tip, to, after.tip);
  }
  return s;
}

}  // namespace surgsim::tool
