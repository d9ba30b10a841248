// tool_size_bench: the instrument's contact against the mesh it touches. The same tip (radius 5 mm) on the shipped
// liver meshed at about 1.4k, 5k and 21k nodes, with the footprint contact (the tip's own size, contact/near_field.h)
// and, side by side in the same run, the earlier node-patch model (Wendland weights over the nodes within the
// radius, no near field) at the radius given in metres and at its old default of 2.5 mean surface edges. And the
// flat-punch indentation of a bottom-fixed slab against the bonded-layer solution (Hayes et al. 1972).
//
// Cases (1 kHz ticks, the tool vertical, one contact point, the shipped scene's law and material):
//   slide  the tip 5 mm below the REST surface (the surface's height under it, found by a vertical ray), moved at
//          2 cm/s for 7 cm along x at y = 1 mm across the liver's curved top; the force along the slide, its mean and
//          its ripple: peak-to-peak of the force minus its 2 cm centred moving average, over its mean (the first and
//          last 1 cm left out: the average needs 1 cm on either side).
//   press  a straight press at 1 cm/s at x = 0.03, y = 1 mm (under the shipped trocar) from 0.5 to 10 mm below the rest
//          surface;
//          the force at each mm of depth.
//   tick   one instrument with 10 contact points 6 mm apart along x, 4 mm below the rest surface, sliding 2 cm along
//          x at 2 cm/s: ToolContacts::step's time per tick (percentiles over 1000 ticks; a timing, not a test).
//   punch  a 20 x 20 x 4 cm slab, bottom fixed, 1 cm and 5 mm cells: the tip pressed 1 mm at 11 positions across a
//          cell; the mean force against 2 a E delta / (1 - nu^2) kappa(a/h, nu).
// Prints tables with the budgets of docs/DESIGN.md ("The instrument's contact") beside each figure; --out DIR writes
//   DIR/tool_size.csv        mesh,model,case,metric,value,unit
//   DIR/tool_size_slide.csv  mesh,model,s_mm,force_N
//   DIR/tool_size_press.csv  mesh,model,depth_mm,force_N
#include <CLI/CLI.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "contact/contact_surface.h"
#include "contact/tool_contacts.h"
#include "csv_out.h"
#include "organs/liver_organ.h"
#include "scene/scene.h"
#include "support/layer_indentation.h"
#include "support/slab_util.h"
#include "mesher/scene_mesh.h"

using namespace surgsim;
using namespace surgsim::contact;
using namespace surgsim::tool;

namespace {

constexpr double kDt = 1e-3;
constexpr double kRadius = 0.005;  // m, the tip of the budgets (a 10 mm instrument)
constexpr double kSlideDepth = 0.005;
constexpr double kSlideSpeed = 0.02;  // m/s
constexpr double kSlideLength = 0.07;
constexpr double kSlideStart = -0.035;
constexpr double kPressX = 0.03;
// The paths run 1 mm off the liver's plane of symmetry (y = 0): the generated meshes have a line of vertices and
// edges there, and a tool descending exactly through it is not detected (a defect of the crossing query, left for the
// defects issue).
constexpr double kY = 0.001;
// Budgets (docs/DESIGN.md, "The instrument's contact").
constexpr double kMeanBudgetPct = 5, kDepthBudgetPct = 5, kRippleBudgetPct = 5, kPunchBudgetPct = 5;

struct Model {
  std::string name;
  TipModel tip;
  double radius;  // m; < 0: -radius mean surface edges
};
const std::vector<Model> kModels = {{"footprint 5 mm", TipModel::kFootprint, kRadius},
                                    {"nodes 5 mm", TipModel::kNodes, kRadius},
                                    {"nodes 2.5 edges", TipModel::kNodes, -2.5}};

struct Out {
  bench::CsvOut figures, slide, press;
  void figure(const std::string& mesh, const std::string& model, const char* c, const char* metric, double v,
              const char* unit) {
    figures.row("%s,%s,%s,%s,%.9g,%s", mesh.c_str(), model.c_str(), c, metric, v, unit);
  }
};

// Height of the rest surface above (x, y): the highest crossing of the vertical line (NaN when none).
double rest_height(const mesh::TetMesh& m, const mesh::SurfaceMesh& s, double x, double y) {
  double best = NAN;
  for (Eigen::Index f = 0; f < s.tris.rows(); ++f) {
    const Eigen::Vector3d a = m.nodes.row(s.tris(f, 0)).transpose(), b = m.nodes.row(s.tris(f, 1)).transpose(),
                          c = m.nodes.row(s.tris(f, 2)).transpose();
    const double d = (b.x() - a.x()) * (c.y() - a.y()) - (b.y() - a.y()) * (c.x() - a.x());
    if (std::abs(d) < 1e-18) continue;
    const double u = ((x - a.x()) * (c.y() - a.y()) - (y - a.y()) * (c.x() - a.x())) / d;
    const double v = ((b.x() - a.x()) * (y - a.y()) - (b.y() - a.y()) * (x - a.x())) / d;
    if (u < -1e-12 || v < -1e-12 || u + v > 1 + 1e-12) continue;
    const double z = a.z() + u * (b.z() - a.z()) + v * (c.z() - a.z());
    if (std::isnan(best) || z > best) best = z;
  }
  return best;
}

double force_of(ToolContacts& c, const Eigen::Vector3d& tip) {
  ContactTick t;
  c.step(test::vertical_tool(tip), 0.5, t, kDt);
  return t.force.norm();
}

// Peak-to-peak of y minus its centred moving average over `window` (in s units), over mean(y), on the samples
// at least window/2 from either end.
double ripple(const std::vector<double>& s, const std::vector<double>& y, double window) {
  double lo = HUGE_VAL, hi = -HUGE_VAL, sum = 0;
  int n = 0;
  for (std::size_t i = 0; i < s.size(); ++i) {
    if (s[i] < s.front() + window / 2 || s[i] > s.back() - window / 2) continue;
    double avg = 0;
    int m = 0;
    for (std::size_t j = 0; j < s.size(); ++j)
      if (std::abs(s[j] - s[i]) <= window / 2) {
        avg += y[j];
        ++m;
      }
    const double r = y[i] - avg / m;
    lo = std::min(lo, r);
    hi = std::max(hi, r);
    sum += y[i];
    ++n;
  }
  return n > 0 && sum > 0 ? (hi - lo) / (sum / n) : 0.0;
}

// The tick with 10 patch contacts (the haptic tick's contact work: tracking, footprints, near field, solve).
void tick_cost(const std::string& label, const std::string& model_name, const liver::LiverModel& model, ToolSpec spec,
               const nonlinear::NonlinearLaw* law, Out& out) {
  constexpr int kPoints = 10;
  constexpr double kSpacing = 0.006, kDepth = 0.004, kX0 = -0.04;
  spec.shaft_points = kPoints;
  spec.shaft_spacing = kSpacing;
  ToolContacts c(model.mesh, model.surface, model.tensors, spec, law);
  c.time_stages(true);
  std::array<std::vector<double>, kContactStages> stage_us;
  // Rest heights along the path, every 0.1 mm (the points move along x only).
  std::vector<double> height;
  for (double x = kX0 - 0.001; x <= kX0 + kPoints * kSpacing + 0.025; x += 1e-4)
    height.push_back(rest_height(model.mesh, model.surface, x, kY));
  const auto h_at = [&](double x) {
    const double f = (x - (kX0 - 0.001)) / 1e-4;
    const auto i = static_cast<std::size_t>(std::clamp(f, 0.0, static_cast<double>(height.size() - 2)));
    return height[i] + (f - static_cast<double>(i)) * (height[i + 1] - height[i]);
  };
  ToolGeometry g{};
  g.direction = {0, 0, -1};
  g.jaw_normal = {1, 0, 0};
  g.point_count = kPoints;
  std::vector<double> us;
  int in_contact = 0;
  for (int k = 0; k < 1300; ++k) {
    const double shift = k < 300 ? 0.0 : (k - 300) * kSlideSpeed * kDt;
    const double depth = k < 300 ? -0.002 + (kDepth + 0.002) * k / 300.0 : kDepth;
    for (int i = 0; i < kPoints; ++i) {
      const double x = kX0 + i * kSpacing + shift;
      g.points[static_cast<std::size_t>(i)] = Eigen::Vector3d(x, kY, h_at(x) - depth);
    }
    g.tip = g.points[0];
    g.trocar = g.tip + Eigen::Vector3d(0, 0, 0.15);
    g.jaw_tips = {g.tip, g.tip};
    ContactTick t;
    const auto t0 = std::chrono::steady_clock::now();
    c.step(g, 0.5, t, kDt);
    const auto t1 = std::chrono::steady_clock::now();
    if (k >= 300) {
      us.push_back(std::chrono::duration<double, std::micro>(t1 - t0).count());
      for (int st = 0; st < kContactStages; ++st)
        stage_us[static_cast<std::size_t>(st)].push_back(1e-3 * c.stage_times().ns[static_cast<std::size_t>(st)]);
      in_contact = std::max(in_contact, t.points_in_contact);
    }
  }
  std::sort(us.begin(), us.end());
  const auto q = [&](double p) { return us[static_cast<std::size_t>(p * static_cast<double>(us.size() - 1))]; };
  out.figure(label, model_name, "tick", "tick_us_p50", q(0.5), "us");
  out.figure(label, model_name, "tick", "tick_us_p99", q(0.99), "us");
  out.figure(label, model_name, "tick", "tick_us_max", us.back(), "us");
  out.figure(label, model_name, "tick", "contacts", in_contact, "points");
  std::printf("  %-16s tick, %d contacts: p50 %.1f / p99 %.1f / max %.1f us (budget p99 <= 100 us: %s)\n",
              model_name.c_str(), in_contact, q(0.5), q(0.99), us.back(), q(0.99) <= 100 ? "pass" : "FAIL");
  std::printf("  %-16s   stages p50 / p99 us:", "");
  for (int st = 0; st < kContactStages; ++st) {
    std::vector<double>& v = stage_us[static_cast<std::size_t>(st)];
    std::sort(v.begin(), v.end());
    std::printf(" %s %.1f / %.1f", kContactStageNames[static_cast<std::size_t>(st)],
                v[static_cast<std::size_t>(0.5 * static_cast<double>(v.size() - 1))],
                v[static_cast<std::size_t>(0.99 * static_cast<double>(v.size() - 1))]);
  }
  std::printf("\n");
}

struct MeshResult {
  std::map<std::string, double> mean;                // model -> mean slide force
  std::map<std::string, double> ripple;              // model -> ripple
  std::map<std::string, std::vector<double>> depth;  // model -> force at 1..10 mm
};

MeshResult run_mesh(const std::string& label, int target_nodes, const std::string& cache, bool tick_only, Out& out) {
  scene::Scene scene = scene::load_scene(scene::resolve_scene_path("liver"));
  scene.mesh.target_nodes = target_nodes;
  LiverOrgan organ(scene, cache, &std::cout);
  const liver::LiverModel& model = organ.model();
  const double edge = ContactSurface::mean_edge(model.mesh, model.surface);
  std::printf("\n%s: %ld nodes, %zu surface nodes, mean surface edge %.1f mm\n", label.c_str(),
              static_cast<long>(model.mesh.nodes.rows()), model.surface.nodes.size(), edge * 1e3);
  MeshResult r;
  for (const Model& m : kModels) {
    ToolSpec spec = scene.tools[0];
    spec.shaft_points = 1;
    spec.contact_capacity = 64;
    spec.tip_model = m.tip;
    spec.tip_radius = m.radius > 0 ? m.radius : -m.radius * edge;
    const nonlinear::NonlinearLaw* law = model.law.identity() ? nullptr : &model.law;
    if (tick_only) {
      tick_cost(label, m.name, model, spec, law, out);
      continue;
    }
    {  // the slide
      ToolContacts c(model.mesh, model.surface, model.tensors, spec, law);
      const auto tip_at = [&](double x, double depth) {
        return Eigen::Vector3d(x, kY, rest_height(model.mesh, model.surface, x, kY) - depth);
      };
      for (int k = 0; k <= 350; ++k)  // from 2 mm above to 5 mm deep at 2 cm/s
        force_of(c, tip_at(kSlideStart, std::min(kSlideDepth, -0.002 + k * kSlideSpeed * kDt)));
      std::vector<double> s, f;
      const int ticks = static_cast<int>(std::lround(kSlideLength / (kSlideSpeed * kDt)));
      for (int k = 0; k <= ticks; ++k) {
        const double x = kSlideStart + k * kSlideSpeed * kDt;
        s.push_back(x - kSlideStart);
        f.push_back(force_of(c, tip_at(x, kSlideDepth)));
        if (k % 10 == 0) out.slide.row("%s,%s,%.2f,%.9g", label.c_str(), m.name.c_str(), 1e3 * s.back(), f.back());
      }
      double mean = 0;
      for (double v : f) mean += v / static_cast<double>(f.size());
      r.mean[m.name] = mean;
      r.ripple[m.name] = 100 * ripple(s, f, 0.02);
      out.figure(label, m.name, "slide", "mean_force", mean, "N");
      out.figure(label, m.name, "slide", "ripple", r.ripple[m.name], "%");
      out.figure(label, m.name, "slide", "tip_radius", 1e3 * spec.tip_radius, "mm");
    }
    {  // the press
      ToolContacts c(model.mesh, model.surface, model.tensors, spec, law);
      const double top = rest_height(model.mesh, model.surface, kPressX, kY);
      std::vector<double> at(10, NAN);
      double prev_d = 0, prev_f = 0;
      // 1 cm/s from 0.5 mm deep to 10 mm deep: the first tick finds the tool inside (as after a reset), so the
      // press does not depend on the crossing query.
      for (int k = 0; k <= 1200; ++k) {
        const double depth = 0.0005 + k * 0.01 * kDt;
        const double f = force_of(c, Eigen::Vector3d(kPressX, kY, top - depth));
        for (int mm = 1; mm <= 10; ++mm)
          if (prev_d < mm * 1e-3 && depth >= mm * 1e-3)
            at[static_cast<std::size_t>(mm - 1)] = prev_f + (f - prev_f) * (mm * 1e-3 - prev_d) / (depth - prev_d);
        prev_d = depth;
        prev_f = f;
        if (depth >= 0.0101) break;
      }
      for (int mm = 1; mm <= 10; ++mm)
        out.press.row("%s,%s,%d,%.9g", label.c_str(), m.name.c_str(), mm, at[static_cast<std::size_t>(mm - 1)]);
      r.depth[m.name] = at;
    }
    std::printf("  %-16s tip %5.1f mm  slide mean %.4f N  ripple %5.1f %%  press 1/5/10 mm %.4f / %.4f / %.4f N\n",
                m.name.c_str(), 1e3 * spec.tip_radius, r.mean[m.name], r.ripple[m.name], r.depth[m.name][0],
                r.depth[m.name][4], r.depth[m.name][9]);
    tick_cost(label, m.name, model, spec, law, out);
  }
  return r;
}

void punch(Out& out) {
  const double h = 0.04, delta = 0.001;
  const fem::Material mat{3000.0, 0.45};
  const double kappa = test::hayes_kappa(kRadius / h, mat.poisson_ratio);
  const double ref = test::hayes_force(kRadius, h, mat.young_modulus, mat.poisson_ratio, delta);
  std::printf(
      "\nflat punch: slab 20 x 20 x 4 cm, bottom fixed, E %.0f Pa, nu %.2f, tip %.0f mm, %.0f mm deep: "
      "Hayes kappa(%.3f) = %.4f, reference %.5f N\n",
      mat.young_modulus, mat.poisson_ratio, kRadius * 1e3, delta * 1e3, kRadius / h, kappa, ref);
  for (int cells : {20, 40}) {
    const test::Slab slab(cells, cells, cells / 5, {0.2, 0.2, h});
    const std::string label = cells == 20 ? "slab 1 cm cells" : "slab 5 mm cells";
    for (const Model& m : kModels) {
      ToolSpec spec;
      spec.shaft_points = 1;
      spec.force_limit = 100;
      spec.contact_capacity = 64;
      spec.tip_model = m.tip;
      spec.tip_radius = m.radius > 0 ? m.radius : -m.radius * 0.2 / cells;
      double sum = 0, lo = HUGE_VAL, hi = 0;
      for (int k = 0; k <= 10; ++k) {  // 11 positions across one cell, off the node lines
        ToolContacts c(slab.mesh, slab.surface, slab.tensors, spec);
        const Eigen::Vector2d xy(0.1 + k * 0.1 * 0.2 / cells, 0.1 + 0.3 * 0.2 / cells);
        double f = 0;
        for (int t = 0; t <= 60; ++t)
          f = force_of(c, Eigen::Vector3d(xy.x(), xy.y(), h + 0.001 - std::min(0.002, t * 0.002 / 40)));
        sum += f / 11;
        lo = std::min(lo, f);
        hi = std::max(hi, f);
      }
      const double err = 100 * (sum / ref - 1);
      out.figure(label, m.name, "punch", "force", sum, "N");
      out.figure(label, m.name, "punch", "reference", ref, "N");
      out.figure(label, m.name, "punch", "error", err, "%");
      out.figure(label, m.name, "punch", "spread", 100 * (hi - lo) / sum, "%");
      std::printf("  %-16s %-16s force %.5f N (%.5f..%.5f)  vs Hayes %+6.1f %%  budget within %g %%: %s\n",
                  label.c_str(), m.name.c_str(), sum, lo, hi, err, kPunchBudgetPct,
                  std::abs(err) <= kPunchBudgetPct ? "pass" : "FAIL");
    }
  }
}

}  // namespace

int main(int argc, char** argv) {
  std::string out_dir, cache;
  std::vector<int> meshes = {1500, 5000, 20000};
  bool no_liver = false, tick_only = false;
  CLI::App cli{
      "tool_size_bench: the instrument's contact on the shipped liver meshed at 1.4k, 5k and 21k nodes "
      "(footprint against the earlier node patch, one run), and the slab's flat punch against Hayes 1972"};
  cli.add_option("--out", out_dir, "Write tool_size.csv, tool_size_slide.csv and tool_size_press.csv here");
  cli.add_option("--cache", cache,
                 "Cache folder for the meshes and tensors (default $SURGSIM_CACHE_DIR or ~/.cache/surgsim)");
  cli.add_option("--meshes", meshes, "Target node counts of the liver meshes; the last is the reference")
      ->delimiter(',');
  cli.add_flag("--no-liver", no_liver, "The slab only (no mesh or tensor cache needed)");
  cli.add_flag("--tick-only", tick_only, "The contact tick's cost on each liver only (no slab, slide or press)");
  CLI11_PARSE(cli, argc, argv);
  try {
    if (!out_dir.empty()) std::filesystem::create_directories(out_dir);
    Out out;
    out.figures = bench::CsvOut(out_dir, "tool_size", "mesh,model,case,metric,value,unit");
    out.slide = bench::CsvOut(out_dir, "tool_size_slide", "mesh,model,s_mm,force_N");
    out.press = bench::CsvOut(out_dir, "tool_size_press", "mesh,model,depth_mm,force_N");
    if (!tick_only) punch(out);
    if (no_liver) return 0;
    std::vector<std::string> labels;
    std::vector<MeshResult> results;
    for (int n : meshes) {
      labels.push_back("liver " + std::to_string(n));
      results.push_back(
          run_mesh(labels.back(), n, cache.empty() ? mesher::default_cache_dir() : cache, tick_only, out));
    }
    if (tick_only) return 0;
    // Against the last (finest) mesh: mean slide force and force at every depth, same model and radius.
    const MeshResult& ref = results.back();
    std::printf("\nagainst %s (same model):\n", labels.back().c_str());
    for (std::size_t i = 0; i + 1 < results.size(); ++i)
      for (const Model& m : kModels) {
        const double mean_err = 100 * (results[i].mean[m.name] / ref.mean.at(m.name) - 1);
        double worst = 0;
        for (std::size_t d = 0; d < 10; ++d) {
          const double e = 100 * (results[i].depth[m.name][d] / ref.depth.at(m.name)[d] - 1);
          if (std::abs(e) > std::abs(worst)) worst = e;
        }
        out.figure(labels[i], m.name, "against_reference", "mean_force_error", mean_err, "%");
        out.figure(labels[i], m.name, "against_reference", "depth_force_worst_error", worst, "%");
        std::printf(
            "  %-12s %-16s slide mean %+6.1f %% (budget %g %%: %s)  force-depth worst %+6.1f %% (budget %g "
            "%%: %s)\n",
            labels[i].c_str(), m.name.c_str(), mean_err, kMeanBudgetPct,
            std::abs(mean_err) <= kMeanBudgetPct ? "pass" : "FAIL", worst, kDepthBudgetPct,
            std::abs(worst) <= kDepthBudgetPct ? "pass" : "FAIL");
      }
    std::printf("\nripple (budget <= %g %% on every mesh):\n", kRippleBudgetPct);
    for (std::size_t i = 0; i < results.size(); ++i)
      for (const Model& m : kModels)
        std::printf("  %-12s %-16s %5.1f %%  %s\n", labels[i].c_str(), m.name.c_str(), results[i].ripple[m.name],
                    results[i].ripple[m.name] <= kRippleBudgetPct ? "pass" : "FAIL");
  } catch (const std::exception& e) {
    std::cerr << "tool_size_bench: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
