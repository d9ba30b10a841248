// haptic_signal_bench: what the hand feels, for the paper's triangle contact and the patch contact side by
// side in one run, on a bottom-fixed slab and on the shipped liver. Prints readable tables; --out DIR writes
//   DIR/haptic_signal.csv        one row per figure: case, model, metric, value, unit
//   DIR/haptic_signal_slide.csv  force against position while sliding at constant depth (slab) and along the shipped
//                                liver_press_slide trajectory (liver): case, model, s_mm, fn_N, ft_N
// Figures: ripple (peak-to-peak of the detrended normal force / its mean) and largest tangential / normal ratio while
// sliding (grid-aligned and at 31.7 degrees), the largest one-tick force change at a 0.1 m/s onset, a 5 mm stab and
// a grasp release (relative to the force held), and the energy the environment gives back over a straight
// press-and-return cycle on the shipped liver (sum of F . dx on the tool: > 0 means the tissue adds energy).
// The device side (coupling, passivity, closed loop through surgsim-device-sim --physical) is measured by
// scripts/report.sh with the real processes.
#include <CLI/CLI.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

#include "csv_out.h"
#include "fem/fem.h"
#include "fem/fixed_set.h"
#include "compliance/precompute.h"
#include "mesh/box_mesh.h"
#include "mesher/scene_mesh.h"
#include "force_stage.h"
#include "contact/tool_contacts.h"
#include "organs/liver_organ.h"
#include "scene/scene.h"
#include "support/slab_util.h"
#include "tool/trajectory.h"

using namespace surgsim::tool;
using namespace surgsim::contact;
using namespace surgsim::intestine;
using namespace surgsim::scene;
using namespace surgsim::mesher;

namespace surgsim {
namespace {

constexpr double kTop = 0.04;  // m, top face of the slab
constexpr double kDt = 1e-3;   // s, 1 kHz

const char* name_of(ContactModel m) { return m == ContactModel::kPatch ? "patch" : "triangle"; }

struct Out {
  bench::CsvOut figures, slide;
  void figure(const std::string& c, const char* model, const char* metric, double v, const char* unit) {
    figures.row("%s,%s,%s,%.9g,%s", c.c_str(), model, metric, v, unit);
    std::printf("  %-34s %-12s %-24s %12.5g %s\n", c.c_str(), model, metric, v, unit);
  }
  void figure(const std::string& c, ContactModel m, const char* metric, double v, const char* unit) {
    figure(c, name_of(m), metric, v, unit);
  }
};
// "patch+stage": the patch contact followed by the haptic node's force stage (coupling damper, passivity observer and
// controller with the shipped scene's defaults): what the device is sent.
constexpr const char* kStaged = "patch+stage";

struct Slab : test::Slab {
  Slab() : test::Slab(20, 20, 4, {0.2, 0.2, 0.04}) {}
  ToolSpec spec(ContactModel m) const {
    ToolSpec s;
    s.shaft_points = 1;
    s.force_limit = 100.0;
    s.contact_capacity = 64;
    s.contact_model = m;
    return s;
  }
};

ContactTick step(ToolContacts& c, const Eigen::Vector3d& tip, double jaw = 0.5) {
  ContactTick t;
  c.step(test::vertical_tool(tip), jaw, t, kDt);
  return t;
}

void slab_slides(const Slab& slab, Out& out) {
  const double golden = 0.5 * (1 + std::sqrt(5.0));
  struct Path {
    const char* name;
    Eigen::Vector3d start, dir;
  };
  const Path paths[] = {{"slab slide grid-aligned", {0.0731, 0.0977, 0}, {1, 0, 0}},
                        {"slab slide 31.7 deg", {0.0731, 0.0777, 0}, Eigen::Vector3d(golden, 1, 0).normalized()}};
  for (const Path& path : paths) {
    for (double depth : {0.001, 0.003}) {
      for (ContactModel m : {ContactModel::kTriangle, ContactModel::kPatch}) {
        ToolContacts c(slab.mesh, slab.surface, slab.tensors, slab.spec(m));
        step(c, path.start + Eigen::Vector3d(0, 0, kTop + 0.002));
        for (int k = 0; k <= 100; ++k)
          step(c, path.start + Eigen::Vector3d(0, 0, kTop - depth * std::min(1.0, k / 50.0)));
        std::vector<double> s, fn;
        double tangential = 0;
        const std::string name = std::string(path.name) + " " + std::to_string(static_cast<int>(depth * 1e3)) + " mm";
        for (int k = 0; k <= 250; ++k) {  // 50 mm in 0.2 mm ticks
          const ContactTick t = step(c, path.start + k * 0.0002 * path.dir + Eigen::Vector3d(0, 0, kTop - depth));
          s.push_back(k * 0.0002);
          fn.push_back(t.force.z());
          const double ft = t.force.head<2>().norm();
          if (t.force.z() > 0) tangential = std::max(tangential, ft / t.force.z());
          out.slide.row("%s,%s,%.4f,%.9g,%.9g", name.c_str(), name_of(m), k * 0.2, t.force.z(), ft);
        }
        double mean = 0;
        for (double f : fn) mean += f / static_cast<double>(fn.size());
        out.figure(name, m, "ripple", 100 * test::detrended_ripple(s, fn), "%");
        out.figure(name, m, "tangential_max", 100 * tangential, "% of normal");
        out.figure(name, m, "normal_mean", mean, "N");
      }
    }
  }
}

void slab_steps(const Slab& slab, Out& out) {
  const Eigen::Vector3d start(0.0731, 0.0977, kTop + 0.003);
  for (ContactModel m : {ContactModel::kTriangle, ContactModel::kPatch}) {
    {  // approach at 0.1 m/s to 6 mm below the start (3 mm deep), hold
      ToolContacts c(slab.mesh, slab.surface, slab.tensors, slab.spec(m));
      double prev = 0, worst = 0, held = 0;
      for (int k = 0; k <= 160; ++k) {
        held = step(c, start + Eigen::Vector3d(0, 0, std::max(-0.006, -1e-4 * k))).force.norm();
        worst = std::max(worst, std::abs(held - prev));
        prev = held;
      }
      out.figure("slab onset 0.1 m/s to 3 mm", m, "step_max", held > 0 ? 100 * worst / held : 0, "% of held");
    }
    if (m == ContactModel::kPatch) {  // the same approach, as the device is sent it (after the force stage)
      ToolContacts c(slab.mesh, slab.surface, slab.tensors, slab.spec(m));
      ForceStage stage(HapticSpec{}, 100.0);
      double prev = 0, moving = 0, stop = 0, held = 0;
      for (int k = 0; k <= 160; ++k) {
        const Eigen::Vector3d tip = start + Eigen::Vector3d(0, 0, std::max(-0.006, -1e-4 * k));
        ContactTick t;
        const ToolGeometry g = test::vertical_tool(tip);
        c.step(g, 0.5, t, kDt);
        stage.apply(g, kDt, t);
        held = t.device_force.norm();
        // Ticks 0..60 move at 0.1 m/s; tick 61 is the first at rest (the scripted tool stops dead).
        (k <= 60 ? moving : stop) = std::max(k <= 60 ? moving : stop, std::abs(held - prev));
        prev = held;
      }
      out.figure("slab onset 0.1 m/s to 3 mm", kStaged, "step_max", held > 0 ? 100 * moving / held : 0, "% of held");
      // The coupling damper's force is B v: a tool that stops dead (scripted; a device with mass cannot) drops it in
      // one tick. Shown apart from the onset.
      out.figure("slab approach stops dead", kStaged, "step_max", held > 0 ? 100 * stop / held : 0, "% of held");
    }
    {  // a 5 mm stab in one tick, hold 100 ms
      ToolContacts c(slab.mesh, slab.surface, slab.tensors, slab.spec(m));
      step(c, start);
      double prev = 0, worst = 0, held = 0;
      for (int k = 0; k < 100; ++k) {
        held = step(c, start + Eigen::Vector3d(0, 0, -0.008)).force.norm();
        worst = std::max(worst, std::abs(held - prev));
        prev = held;
      }
      out.figure("slab stab 5 mm in one tick", m, "step_max", held > 0 ? 100 * worst / held : 0, "% of held");
    }
    {  // a grasp pulled 3 mm above the rest surface, then released
      ToolContacts c(slab.mesh, slab.surface, slab.tensors, slab.spec(m));
      for (int k = 0; k <= 60; ++k) step(c, start + Eigen::Vector3d(0, 0, std::max(-0.006, -1e-4 * k)));
      for (int k = 0; k < 10; ++k) step(c, start + Eigen::Vector3d(0, 0, -0.006), 0.0);
      ContactTick t;
      for (int k = 0; k <= 60; ++k) t = step(c, start + Eigen::Vector3d(0, 0, -0.006 + 1e-4 * k), 0.0);
      const double held = t.force.norm();
      double prev = held, worst = 0;
      for (int k = 0; k < 100; ++k) {
        t = step(c, start, 0.5);
        worst = std::max(worst, std::abs(t.force.norm() - prev));
        prev = t.force.norm();
      }
      out.figure("slab grasp release", m, "step_max", held > 0 ? 100 * worst / held : 0, "% of held");
    }
  }
}

void liver_runs(const std::string& cache, Out& out) {
  for (ContactModel m : {ContactModel::kTriangle, ContactModel::kPatch}) {
    Scene scene = load_scene(resolve_scene_path("liver"));
    scene.tools[0].contact_model = m;
    LiverOrgan organ(scene, cache, nullptr);
    // Straight press at 0.1 m/s from 1 cm above to 45 mm deep and back: monotonic? energy returned?
    Pose5 p;
    p.jaw = 0.5;
    double prev = 0, largest_drop = 0, energy = 0, force_at_5mm = -1, first_contact_z = 0;
    Eigen::Vector3d tip_prev = Eigen::Vector3d::Zero();
    Eigen::Vector3d f_prev = Eigen::Vector3d::Zero();
    const int half = 600;  // 60 mm of travel each way at 0.1 mm per tick
    for (int k = 0; k <= 2 * half; ++k) {
      const int j = k <= half ? k : 2 * half - k;
      p.insertion = 0.15 + 1e-4 * j;
      const ToolGeometry g = tool_geometry(scene.tools[0], p);
      ContactTick t;
      organ.step(&g, p.jaw, kDt, t);
      const Eigen::Vector3d f = t.force;  // on the tool, before the device clamp
      if (k > 0) energy += 0.5 * (f + f_prev).dot(g.tip - tip_prev);  // trapezoid: work on the tool
      if (k <= half) largest_drop = std::max(largest_drop, prev - f.norm());
      if (k <= half && t.points_in_contact > 0 && first_contact_z == 0) first_contact_z = g.tip.z();
      if (k <= half && force_at_5mm < 0 && first_contact_z != 0 && first_contact_z - g.tip.z() >= 0.005)
        force_at_5mm = t.device_force.norm();
      prev = f.norm();
      tip_prev = g.tip;
      f_prev = f;
    }
    out.figure("liver straight press to 60 mm", m, "largest_force_drop_in", largest_drop, "N");
    out.figure("liver straight press to 60 mm", m, "force_5mm_past_contact", force_at_5mm, "N");
    out.figure("liver press and return", m, "energy_returned", 1e3 * energy, "mJ");
    if (m == ContactModel::kPatch) {  // the same cycle as the device is sent it (after the force stage)
      LiverOrgan staged_organ(scene, cache, nullptr);
      ForceStage stage(scene.haptic, scene.tools[0].force_limit);
      double e = 0;
      Eigen::Vector3d tp = Eigen::Vector3d::Zero(), fp = Eigen::Vector3d::Zero();
      for (int k = 0; k <= 2 * half; ++k) {
        const int j = k <= half ? k : 2 * half - k;
        p.insertion = 0.15 + 1e-4 * j;
        const ToolGeometry g = tool_geometry(scene.tools[0], p);
        ContactTick t;
        staged_organ.step(&g, p.jaw, kDt, t);
        stage.apply(g, kDt, t);
        if (k > 0) e += 0.5 * (t.device_force + fp).dot(g.tip - tp);
        tp = g.tip;
        fp = t.device_force;
      }
      out.figure("liver press and return", kStaged, "energy_returned", 1e3 * e, "mJ");
      out.figure("liver press and return", kStaged, "observer_energy_min", 1e3 * stage.energy_min(), "mJ");
    }
    // The shipped liver_press_slide trajectory: force against time (the plot), and the ripple of the slide phase.
    const Trajectory traj = Trajectory::load(config_dir() + "/trajectories/liver_press_slide.csv");
    LiverOrgan fresh(scene, cache, nullptr);
    const int ticks = static_cast<int>(traj.duration() / kDt);
    for (int k = 0; k <= ticks; ++k) {
      const Pose5 q = traj.at(k * kDt);
      const ToolGeometry g = tool_geometry(scene.tools[0], q);
      ContactTick t;
      fresh.step(&g, q.jaw, kDt, t);
      const double fn = t.direction.norm() > 0 ? -t.force.dot(t.direction) : t.force.norm();
      const double ft = (t.force + fn * t.direction).norm();
      out.slide.row("liver_press_slide,%s,%.4f,%.9g,%.9g", name_of(m), k * kDt * 1e3, fn, ft);
    }
  }
}

}  // namespace
}  // namespace surgsim

int main(int argc, char** argv) {
  using namespace surgsim;
  std::string out_dir, cache;
  bool no_liver = false;
  CLI::App cli{"haptic_signal_bench: ripple, tangential force, onset and release steps and energy of the liver's "
               "contact, triangle (paper) against patch, on a bottom-fixed slab and the shipped liver"};
  cli.add_option("--out", out_dir, "Write haptic_signal.csv and haptic_signal_slide.csv into this folder");
  cli.add_option("--cache", cache, "Cache folder for the liver's mesh and tensors (default $SURGSIM_CACHE_DIR or ~/.cache/surgsim)");
  cli.add_flag("--no-liver", no_liver, "Slab only (no shipped liver: no mesh or tensor cache needed)");
  CLI11_PARSE(cli, argc, argv);
  try {
    if (!out_dir.empty()) std::filesystem::create_directories(out_dir);
    Out out;
    out.figures = bench::CsvOut(out_dir, "haptic_signal", "case,model,metric,value,unit");
    out.slide = bench::CsvOut(out_dir, "haptic_signal_slide", "case,model,s_mm,fn_N,ft_N");
    std::printf("haptic_signal_bench: slab 20 x 20 x 4 cm (1 cm cells, bottom fixed), 1 kHz\n");
    const Slab slab;
    slab_slides(slab, out);
    slab_steps(slab, out);
    if (!no_liver) {
      std::printf("haptic_signal_bench: shipped liver (config/liver.yaml)\n");
      liver_runs(cache.empty() ? default_cache_dir() : cache, out);
    }
  } catch (const std::exception& e) {
    std::cerr << "haptic_signal_bench: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
