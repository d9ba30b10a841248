// Scissors: the surface the two blades swept closed between two poses of an instrument, the surface a cut follows.
//
// The blades are the instrument's jaws (tool.h): two segments of jaw_length from the pivot at the tip, at +- jaw / 2
// in the jaw plane. Tissue caught between them is severed along the part of the jaw plane they close over: when the
// jaw closes from one tick to the next, each blade sweeps the quadrilateral (pivot before, blade tip before, blade tip
// after, pivot after), returned as two triangles (one when the pivot did not move: the sliver between the blade's two
// positions). Over a whole closure from an angle theta in n steps the two blades' triangles add up to the circular
// sector of angle theta the blade tips draw (area theta L^2 / 2 as n grows; the chords fall short of the arcs by
// O(1 / n^2)). A jaw that opens or holds cuts nothing: closed blades pushed through tissue press it, as the grasper
// does. Plain data, no allocation.
#pragma once
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>

#include "tool/tool.h"

namespace surgsim::tool {

struct BladeTriangle {
  std::array<Eigen::Vector3d, 3> p;  // m, world
  double area() const;
};

/// What the blades swept in one tick: up to two triangles per blade (degenerate ones, below 1e-12 m^2, left out).
struct BladeSweep {
  int count = 0;
  std::array<BladeTriangle, 4> triangles{};
  double area() const;
};

/// The surface swept closed between `before` (jaw angle jaw_before, rad) and `after` (jaw_after): empty unless the
/// jaw closed (jaw_after < jaw_before) and both geometries are finite.
BladeSweep blade_sweep(const ToolGeometry& before, double jaw_before, const ToolGeometry& after, double jaw_after);

}  // namespace surgsim::tool
