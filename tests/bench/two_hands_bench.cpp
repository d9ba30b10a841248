// two_hands_bench: two instruments on the shipped liver, coupled through the tissue. Replays the shipped
// two-instrument trajectory (config/liver_two_tools.yaml: a grasper holding the free lobe, a probe pressing beside
// it) tick by tick at 1 kHz, in one run:
//  1. the tick: both instruments' contacts in one solve (ToolContacts with the scene's law) plus each instrument's
//     force stage, with each instrument's contact capacity set to --capacity (10: the 2 instruments x 10
//     contacts), percentiles over the ticks where both instruments touch, against the 100 us budget;
//  2. the coupling: the grasper's force while the probe presses, from the two-instrument solve, from the grasper alone
//     (the same path, no probe), and from a direct solve of the elasticity with both instruments' constraints built
//     from geometry (tests/support/direct_solve.h: its own stiffness, patches, offsets and near fields from the mesh,
//     the material, the fixed nodes and the tool points' positions; which points touch, and where the grasp closed,
//     are taken from the contacts' flags); linear (no law), the shipped capacities, ticks past every contact's onset
//     ramp.
// A plain program (never a pass/fail test): prints tables; --out DIR writes DIR/two_hands.csv (one row per figure:
// metric, value, unit) and DIR/two_hands_trace.csv (per 10 ms: t, forces of each run).
#include <CLI/CLI.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <string>
#include <vector>

#include "core/clock.h"
#include "core/error.h"
#include "core/stats.h"
#include "csv_out.h"
#include "force_stage.h"
#include "fem/fem.h"
#include "liver/liver_setup.h"
#include "nonlinear/nonlinear_law.h"
#include "compliance/tensor_cache.h"
#include "mesher/scene_mesh.h"
#include "contact/tool_contacts.h"
#include "scene/scene.h"
#include "support/direct_solve.h"
#include "tool/trajectory.h"

using namespace surgsim::core;
using namespace surgsim::mesh;
using namespace surgsim::tool;
using namespace surgsim::fem;
using namespace surgsim::compliance;
using namespace surgsim::nonlinear;
using namespace surgsim::contact;
using namespace surgsim::liver;
using namespace surgsim::scene;
using namespace surgsim::mesher;

namespace surgsim {
namespace {

constexpr double kDt = 1e-3;  // s, 1 kHz

struct Run {
  std::vector<ToolGeometry> geometry;
  std::vector<InstrumentInput> inputs;
  std::vector<ContactTick> out;
};

// Instrument i's input at time t from the trajectory (track[i]: its column group).
void inputs_at(const Scene& scene, const MultiTrajectory& traj, const std::vector<int>& track, double t, Run& r) {
  const std::size_t n = scene.tools.size();
  r.geometry.resize(n);
  r.inputs.resize(n);
  r.out.assign(n, ContactTick{});
  for (std::size_t i = 0; i < n; ++i) {
    Pose5 p;
    const bool ok = traj.at(track[i], t, p);
    r.geometry[i] = tool_geometry(scene.tools[i], p);
    r.inputs[i] = InstrumentInput{ok ? &r.geometry[i] : nullptr, p.jaw};
  }
}

int run(const std::string& scene_arg, const std::string& cache_arg, int capacity, const std::string& out_dir) {
  const Scene scene = load_scene(resolve_scene_path(scene_arg));
  if (scene.tools.size() < 2)
    throw_error(scene.file, ": has ", scene.tools.size(), " instrument (give a scene with two)");
  if (scene.trajectory.empty()) throw_error(scene.file, ": has no trajectory to replay");
  const std::string cache = cache_arg.empty() ? default_cache_dir() : cache_arg;
  const TetMesh mesh = load_scene_mesh(scene, cache, &std::cerr);
  const SurfaceMesh surface = boundary_surface(mesh);
  const LiverTensorSetup setup = liver_tensor_setup(scene.material, scene.fixed, mesh, cache, scene.file);
  const Tensors tensors = load_liver_tensors(setup, mesh, scene.material, {"haptic"}, &std::cerr, nullptr, scene.file);
  const NonlinearLaw law = load_nonlinear_law(scene.nonlinear, scene.material);
  const test::DirectReference direct(mesh.nodes, mesh.tets, scene.material.young_modulus, scene.material.poisson_ratio,
                                     setup.fixed.fixed_nodes());
  if (!direct.ok()) throw_error(scene.file, ": K_ff could not be factored for the direct solve");

  const MultiTrajectory traj = MultiTrajectory::load(scene.trajectory);
  std::vector<int> track;
  for (const ToolSpec& t : scene.tools) {
    track.push_back(traj.find(t.name));
    if (track.back() < 0) throw_error(scene.trajectory, ": no instrument '", t.name, "'");
  }
  const std::uint64_t ticks = static_cast<std::uint64_t>(std::llround(traj.duration() / kDt)) + 1;
  bench::CsvOut figures(out_dir, "two_hands", "metric,value,unit");
  bench::CsvOut trace(out_dir, "two_hands_trace",
                      "t_s,grasper_fz_N,grasper_alone_fz_N,grasper_direct_fz_N,probe_fz_N,probe_alone_fz_N,"
                      "grasper_contacts,probe_contacts");
  const auto figure = [&](const char* metric, double v, const char* unit) {
    figures.row("%s,%.9g,%s", metric, v, unit);
    std::printf("  %-44s %14.6g %s\n", metric, v, unit);
  };
  std::printf(
      "two_hands_bench: scene %s (%d nodes, %zu surface nodes), %zu instruments (%s, %s), trajectory %s, "
      "%llu ticks at 1 kHz\n",
      scene.file.c_str(), static_cast<int>(mesh.nodes.rows()), surface.nodes.size(), scene.tools.size(),
      scene.tools[0].name.c_str(), scene.tools[1].name.c_str(), scene.trajectory.c_str(),
      static_cast<unsigned long long>(ticks));

  // --- 1. the tick, the 2 instruments x `capacity` contacts (then the scene's own capacities), the law and
  // each force stage ---
  for (const int cap : {capacity, 0}) {
    std::vector<ToolSpec> tools = scene.tools;
    if (cap > 0)
      for (ToolSpec& t : tools) t.contact_capacity = cap;
    const std::string tag = cap > 0 ? "" : "_shipped_capacity";
    const auto fig = [&](const char* metric, double v, const char* unit) { figure((metric + tag).c_str(), v, unit); };
    ToolContacts c(mesh, surface, tensors, tools, law.identity() ? nullptr : &law);
    std::vector<ForceStage> stages;
    for (const ToolSpec& t : tools) stages.emplace_back(scene.haptic, t.force_limit);
    SampleRecorder both_us(ticks + 16), all_us(ticks + 16);
    int max_nodes[2] = {0, 0};
    std::uint64_t over = 0, both_ticks = 0;
    Run r;
    for (std::uint64_t k = 0; k < ticks; ++k) {
      inputs_at(scene, traj, track, static_cast<double>(k) * kDt, r);
      const std::uint64_t t0 = monotonic_ns();
      c.step(r.inputs.data(), static_cast<int>(tools.size()), r.out.data(), kDt);
      for (std::size_t i = 0; i < tools.size(); ++i) stages[i].apply(r.inputs[i].tool, kDt, r.out[i]);
      const double us = static_cast<double>(monotonic_ns() - t0) * 1e-3;
      all_us.add(us);
      const bool both = c.instrument_nodes(0) > 0 && c.instrument_nodes(1) > 0;
      if (both) {
        both_us.add(us);
        ++both_ticks;
      }
      for (int i = 0; i < 2; ++i) max_nodes[i] = std::max(max_nodes[i], c.instrument_nodes(i));
      if (r.out[0].over_capacity || r.out[1].over_capacity) ++over;
    }
    const Percentiles b = both_us.summary(), a = all_us.summary();
    std::printf(
        "\n1. Tick (contacts of both instruments in one solve + law + force stages), contact capacity %s per "
        "instrument, us:\n",
        cap > 0 ? std::to_string(cap).c_str() : "of the scene");
    std::printf("  %-22s %8s %8s %8s %8s %8s\n", "ticks", "count", "p50", "p90", "p99", "max");
    std::printf("  %-22s %8llu %8.1f %8.1f %8.1f %8.1f\n", "both touching", static_cast<unsigned long long>(both_ticks),
                b.p50, b.p90, b.p99, b.max);
    std::printf("  %-22s %8llu %8.1f %8.1f %8.1f %8.1f\n", "all", static_cast<unsigned long long>(ticks), a.p50, a.p90,
                a.p99, a.max);
    fig("tick_both_touching_p50_us", b.p50, "us");
    fig("tick_both_touching_p99_us", b.p99, "us");
    fig("tick_both_touching_max_us", b.max, "us");
    fig("tick_all_p99_us", a.p99, "us");
    fig("tick_budget_p99_us", 100.0, "us");
    fig("ticks_both_touching", static_cast<double>(both_ticks), "ticks");
    fig("contact_nodes_max_grasper", max_nodes[0], "nodes");
    fig("contact_nodes_max_probe", max_nodes[1], "nodes");
    fig("ticks_over_capacity", static_cast<double>(over), "ticks");
    std::printf("  verdict: tick p99 with both instruments touching %.1f us against the 100 us budget: %s\n", b.p99,
                b.p99 <= 100.0 ? "within" : "OVER");
  }

  // --- 2. the coupling: the grasper's force with the probe, alone, and from the direct solve (linear) ---
  {
    ToolContacts both(mesh, surface, tensors, scene.tools, nullptr);
    ToolContacts grasper(mesh, surface, tensors, std::vector<ToolSpec>{scene.tools[0]}, nullptr);
    ToolContacts probe(mesh, surface, tensors, std::vector<ToolSpec>{scene.tools[1]}, nullptr);
    Run r, rg, rp;
    double err_max = 0, coupling_max = 0, coupling_at = 0, grasp_alone_at = 0, grasp_both_at = 0;
    std::uint64_t compared = 0;
    // Where each instrument's tip was when its grasp closed (the grasped material point is its rest point then).
    std::array<Eigen::Vector3d, 2> grasp_tip{};
    std::array<bool, 2> grasping{};
    std::printf("\n2. Coupling: the grasper's force (N, z) while the probe presses, linear (no law)\n");
    std::printf("  %7s | %10s %10s %10s %9s | %10s %10s | %s\n", "t (s)", "grasper", "alone", "direct", "rel err",
                "probe", "alone", "contacts g/p");
    for (std::uint64_t k = 0; k < ticks; ++k) {
      const double t = static_cast<double>(k) * kDt;
      inputs_at(scene, traj, track, t, r);
      both.step(r.inputs.data(), 2, r.out.data(), kDt);
      for (int ti = 0; ti < 2; ++ti) {
        const auto sti = static_cast<std::size_t>(ti);
        const bool g = both.point(0, ti).grasp;
        if (g && !grasping[sti]) grasp_tip[sti] = r.geometry[sti].points[0];
        grasping[sti] = g;
      }
      rg = r;
      grasper.step(rg.inputs.data(), 1, rg.out.data(), kDt);
      rp.geometry = r.geometry;
      rp.inputs = {InstrumentInput{r.inputs[1].tool != nullptr ? &rp.geometry[1] : nullptr, r.inputs[1].jaw}};
      rp.out.assign(1, ContactTick{});
      probe.step(rp.inputs.data(), 1, rp.out.data(), kDt);
      // The direct solve wherever the grasper holds and the probe presses (no fading hold in either run).
      double direct_z = std::nan(""), err = std::nan("");
      bool comparable = r.out[0].grasp && r.out[1].points_in_contact > 0;
      std::vector<test::ReferenceContact> contacts;
      for (int ti = 0; ti < 2 && comparable; ++ti) {
        const auto sti = static_cast<std::size_t>(ti);
        for (int i = 0; i < scene.tools[sti].shaft_points; ++i) {
          const PointContact& pc = both.point(i, ti);
          if (pc.release_age >= 0) comparable = false;
          if (both.patch(i, ti).count == 0 || !(pc.grasp || pc.active)) continue;
          if (!pc.grasp && pc.age < ToolContacts::kOnsetRamp) comparable = false;  // its penetration still blending in
          test::ReferenceContact rc;
          rc.instrument = ti;
          rc.tip = r.geometry[sti].points[static_cast<std::size_t>(i)];
          rc.axis = r.geometry[sti].direction;
          rc.radius = scene.tools[0].tip_radius;  // the solve takes the first instrument's tip radius
          rc.grasp = pc.grasp;
          rc.grasp_tip = grasp_tip[sti];
          contacts.push_back(rc);
        }
      }
      if (comparable) {
        const std::vector<Eigen::Vector3d> d = direct.forces(contacts, 2);
        direct_z = d[0].z();
        err = std::max((r.out[0].force - d[0]).norm() / d[0].norm(), (r.out[1].force - d[1]).norm() / d[1].norm());
        err_max = std::max(err_max, err);
        ++compared;
        const double coupling = (r.out[0].force - rg.out[0].force).norm() / rg.out[0].force.norm();
        if (coupling > coupling_max) {
          coupling_max = coupling;
          coupling_at = t;
          grasp_alone_at = rg.out[0].force.z();
          grasp_both_at = r.out[0].force.z();
        }
      }
      if (k % 10 == 0) {
        trace.row("%.3f,%.9g,%.9g,%.9g,%.9g,%.9g,%d,%d", t, r.out[0].force.z(), rg.out[0].force.z(), direct_z,
                  r.out[1].force.z(), rp.out[0].force.z(), both.instrument_nodes(0), both.instrument_nodes(1));
      }
      if (k % 250 == 0) {
        std::printf("  %7.3f | %10.5f %10.5f %10.5f %9.2g | %10.5f %10.5f | %d/%d\n", t, r.out[0].force.z(),
                    rg.out[0].force.z(), direct_z, err, r.out[1].force.z(), rp.out[0].force.z(),
                    both.instrument_nodes(0), both.instrument_nodes(1));
      }
    }
    figure("ticks_compared_with_direct_solve", static_cast<double>(compared), "ticks");
    figure("max_rel_error_vs_direct_solve", err_max, "1");
    figure("grasper_force_change_by_probe_max", 100 * coupling_max, "%");
    figure("grasper_fz_alone_at_max", grasp_alone_at, "N");
    figure("grasper_fz_with_probe_at_max", grasp_both_at, "N");
    figure("time_of_max_coupling", coupling_at, "s");
    std::printf(
        "  verdict: largest relative difference from the direct solve %.2g (budget 1e-9: %s); the probe "
        "changes the grasper's force by up to %.1f %% (at t = %.3f s: %.4f N alone, %.4f N with the probe)\n",
        err_max, compared > 0 && err_max <= 1e-9 ? "within" : "OVER or nothing compared", 100 * coupling_max,
        coupling_at, grasp_alone_at, grasp_both_at);
  }
  return 0;
}

}  // namespace
}  // namespace surgsim

int main(int argc, char** argv) {
  CLI::App cli{
      "two_hands_bench: the tick with two instruments on the shipped liver, and the grasper's "
      "force while the probe presses, against the same grasper alone and a direct solve"};
  std::string scene = "liver_two_tools", cache, out;
  int capacity = 10;
  cli.add_option("--scene", scene, "two-instrument scene (file or shipped name)")->capture_default_str();
  cli.add_option("--cache", cache, "mesh and tensor cache folder (default: the nodes' cache)");
  cli.add_option("--capacity", capacity, "contact nodes per instrument for the tick measure")
      ->check(CLI::Range(1, 32))
      ->capture_default_str();
  cli.add_option("--out", out, "write two_hands.csv and two_hands_trace.csv into this folder");
  CLI11_PARSE(cli, argc, argv);
  try {
    return surgsim::run(scene, cache, capacity, out);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "two_hands_bench: %s\n", e.what());
    return 1;
  }
}
