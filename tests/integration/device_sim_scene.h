// The two-instrument scene of the surgsim-device-sim tests: the shipped liver (same mesh, material, fixed
// set and curves, so its cached tensors serve) with two straight probes coming down onto its top, 6 cm apart:
// "left" over x = 0 (top surface near z = 0.040) and "right" over x = 0.06 (near z = 0.042). At insertion 0.155 both
// tips are 3-5 mm above the surface, as the shipped liver's single tool.
#pragma once
#include <fstream>
#include <stdexcept>
#include <string>

namespace surgsim::testing {

/// Writes the scene to `file` (the shipped curves by absolute path) and returns `file`.
inline std::string write_two_probe_liver(const std::string& file) {
  const std::string config = SURGSIM_TEST_CONFIG_DIR;
  const std::string probe =
      "axis: [0, 0, -1], shaft_length: 0.35, shaft_radius: 0.0025, shaft_points: 4, shaft_spacing: 0.01, "
      "jaw_length: 0.015, force_limit: 8.0, contact_capacity: 32, contact_model: patch, friction: 0.0, "
      "tip_radius: 0.0125}\n";
  std::ofstream out(file);
  out << "name: liver_two_probes\n"
         "model: liver\n"
         "mesh:\n"
         "  generate: liver\n"
         "  target_nodes: 1500\n"
         "material:\n"
         "  young_modulus: 3000.0\n"
         "  poisson_ratio: 0.45\n"
         "nonlinear:\n"
         "  displacement_curve: " << config << "/curves/liver_dr.csv\n"
         "  force_curve: " << config << "/curves/liver_force.csv\n"
         "  degree: 6\n"
         "fixed:\n"
         "  plane: {point: [0, 0, -0.025], normal: [0, 0, -1]}\n"
         "tools:\n"
         "  - {name: left, trocar: [0.0, 0.0, 0.20], " << probe <<
         "  - {name: right, trocar: [0.06, 0.0, 0.20], " << probe <<
         "haptic:\n"
         "  rate_hz: 1000\n";
  if (!out) throw std::runtime_error("cannot write " + file);
  return file;
}

}  // namespace surgsim::testing
