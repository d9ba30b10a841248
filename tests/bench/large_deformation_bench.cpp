// large_deformation_bench: the liver at large deformation, every method against the neo-Hookean Newton
// reference (common/fem/hyperelastic.h) on the shipped liver, in one run. A plain program run by hand
// (build/bench/large_deformation_bench --out DIR [--quick]); tables on stdout, progress on stderr.
//
// Cases (constraints: every component of the constrained nodes imposed, as liver_error_bench's non-linear study):
//   indent_5 .. indent_30   the flat punch of liver_error_bench (free top nodes within 2 cm of (0.03, 0)) pushed down
//                           by 5 .. 30 % of the organ's height;
//   lift_45, lift_90        the free left lobe (x < -0.075 hangs below the clamp's reach) grasped on its top within
//                           1.2 cm of (-0.100, 0.010) and turned rigidly about the y axis through (-0.070, 0.010,
//                           -0.010) by 45 and 90 degrees (the grasp lifts and turns; the rest of the lobe follows);
//   rigid_90                the whole organ with its fixed set turned 90 degrees about (1, 1, 1) and moved by
//                           (2, -3, 5) cm, the punch nodes held where that carries them: the reference force is 0,
//                           so force_rel_error is |F| / |F_Newton(indent_10)| (the issue's "1 % of a 10 %
//                           indentation"), disp_rel_error against the rigid displacement.
// Methods: linear (lambda = G_CC^-1 u*, the tensors as precomputed), quasi_cylinder (the law with the scene's
// cylinder curves, as the nodes apply it), quasi_organ (the law with Q fitted on the organ's own Newton
// indentations, nonlinear/organ_curves.h, cached in --cache; no P, as in the scenes), corotational (W = R_i G R_j^T,
// compliance/corotation.h, the rotations iterated to a fixed point from the rest-frame response; the free configuration
// is the rest shape carried by the fixed set's rigid frame), corotational_organ (corotational, then the organ law).
// Errors: force = |F - F_ref| / |F_ref| of the total tool force (vectors); disp = |u - u_ref| / |u_ref| over the
// visible (boundary) nodes. tick_us_p99: the haptic side of one tick for that case (linear: the G_CC solve; quasi: +
// Q; corotational: the contact nodes' rotations from the rest-frame field, the warped prepare, factor and solve),
// wall clock, 99th percentile of --repeats.
// Diagnostic rows on stdout only (corot_true_rot): the corotational force with the rotations of the Newton
// reference's own displacement field, which tells an error of the rotation estimate from one of the formulation.
// Then, without a reference: the haptic tick of ToolContacts (patch model, one instrument pressing 8 mm on the
// shipped liver; and a solve of exactly 10 contact nodes), linear against corotational, and the visual node's
// SurfaceDeformer::apply for 10 contacts, linear against corotational (the rotations recomputed there).
//
// multirate (nonlinear/multirate.h): a slow neo-Hookean tracker publishing f_c and the contact stiffness S, the 1 kHz
// loop evaluating f_c + S du. Its static row (the tool held at the target until the tracker converged) is Newton's
// tolerance by construction. The honest figure is the motion table: the tool moved from rest to each case's target
// (straight press, circular lift) in --durations, the slow side emulated in step (a cycle starts when the previous
// ends and its snapshot is visible to the loop after the cycle's measured wall time; the haptic side hands it the
// tool's position extrapolated by the last cycle's time unless --no-predict), the force error at every tick against
// the Newton quasi-static force at the same tool position (a converged continuation along the path at
// --motion-samples points). --slow-cycle-only times the slow cycle alone (e.g. on the 5k liver: --nodes 5000).
// CSV (with --out DIR): liver_large_deformation.csv  case,method,force_rel_error,disp_rel_error,tick_us_p99
//   liver_large_deformation_motion.csv  case,method,duration_s,force_rel_error_p99,force_rel_error_max,
//                                       slow_cycle_ms_p50,slow_cycle_ms_p99
// Plot: scripts/report/large_deformation.py.
#include <CLI/CLI.hpp>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "bench_util.h"
#include "core/error.h"
#include "csv_out.h"
#include "compliance/corotation.h"
#include "fem/hyperelastic.h"
#include "liver/liver_setup.h"
#include "nonlinear/multirate.h"
#include "nonlinear/nonlinear_law.h"
#include "nonlinear/organ_curves.h"
#include "compliance/patch_solve.h"
#include "liver_bench_organ.h"
#include "contact/tool_contacts.h"
#include "views/surface_deformer.h"

using namespace surgsim::mesh;
using namespace surgsim::tool;
using namespace surgsim::fem;
using namespace surgsim::compliance;
using namespace surgsim::nonlinear;
using namespace surgsim::contact;
using namespace surgsim::liver;
using namespace surgsim::intestine;
using namespace surgsim::scene;
using namespace surgsim::mesher;

namespace {

using namespace surgsim;
using namespace surgsim::bench_liver;
using Clock = bench::WallClock;
using bench::us_since;

constexpr double kPi = 3.14159265358979323846;

void progress(const std::string& what) { std::cerr << "large_deformation_bench: " << what << std::endl; }

// One case: the constrained nodes, their imposed world displacements, the fixed set's rigid frame and the reference.
struct Case {
  std::string name;
  double angle = 0;                  // degrees (lift, rigid), for the plot
  double depth_percent = 0;          // indentation % (indent)
  std::vector<int> nodes;
  std::vector<Eigen::Vector3d> u_star;  // m
  RigidFrame base;                   // identity unless the fixed set moves
  bool rigid = false;                // reference is the rigid motion itself
  bool lift = false;                 // the path is a turn about `hinge` (else straight from rest)
  Eigen::Vector3d hinge = Eigen::Vector3d::Zero();
  Eigen::Vector3d f_ref = Eigen::Vector3d::Zero();
  Eigen::VectorXd u_ref;             // visible, m
  Eigen::MatrixX3d newton_u;         // #V x 3, m (not for rigid)
  bool converged = true;
};

struct Outcome {
  Eigen::Vector3d force = Eigen::Vector3d::Zero();
  Eigen::VectorXd u;  // visible
  std::vector<double> tick_us;
};

// The corotational solve of a case: rows x, y, z per node (weight 1 each), rotations iterated to a fixed point.
class Corotational {
 public:
  Corotational(const Organ& o, const Tensors& t)
      : organ_(o), tensors_(t), solver_(t, "haptic"), visual_(t, "visual"), rot_(o.mesh, boundary_surface(o.mesh)) {}

  /// `given`: rotations from this whole-mesh displacement field (#V x 3, world) instead of the fixed point (a
  /// diagnostic: the Newton reference's own rotations).
  Outcome solve(const Case& c, int repeats, const Eigen::MatrixX3d* given = nullptr) {
    const int n = static_cast<int>(c.nodes.size());
    PatchConstraints k;
    k.clear();
    for (int u = 0; u < n; ++u) {
      k.nodes[static_cast<std::size_t>(u)] = c.nodes[static_cast<std::size_t>(u)];
      k.entry_node[static_cast<std::size_t>(u)] = u;
      k.entry_weight[static_cast<std::size_t>(u)] = 1;
      k.patch_start[static_cast<std::size_t>(u + 1)] = u + 1;
      for (int r = 0; r < 3; ++r) {
        k.row_patch[static_cast<std::size_t>(3 * u + r)] = u;
        k.row_direction[static_cast<std::size_t>(3 * u + r)] = Eigen::Matrix3d::Identity().col(r);
      }
    }
    k.node_count = k.patch_count = n;
    k.row_count = 3 * n;
    // b: the imposed displacement beyond the free configuration (the rest shape carried by the fixed set's frame).
    std::vector<double> b(static_cast<std::size_t>(3 * n)), mu(static_cast<std::size_t>(3 * n));
    for (int u = 0; u < n; ++u) {
      const Eigen::Vector3d x0 = organ_.mesh.nodes.row(c.nodes[static_cast<std::size_t>(u)]).transpose();
      const Eigen::Vector3d d = c.u_star[static_cast<std::size_t>(u)] - (c.base.apply(x0) - x0);
      for (int r = 0; r < 3; ++r) b[static_cast<std::size_t>(3 * u + r)] = d[r];
    }
    const TensorBlock& vis = visual_.block();
    rot_.reset();
    ut_ = Eigen::MatrixX3d::Zero(organ_.mesh.nodes.rows(), 3);
    std::array<Eigen::Matrix3d, kMaxContacts> r;
    std::array<Eigen::Vector3d, kMaxContacts> lambda, rest_lambda;
    Eigen::VectorXd uv(3 * vis.row_count());
    const auto rotation = [&](int node) -> Eigen::Matrix3d { return c.base.r * rot_.rotation(node); };
    const auto disp = [&](int node) -> Eigen::Vector3d { return ut_.row(node).transpose(); };
    const auto one_pass = [&]() {
      for (int u = 0; u < n; ++u) r[static_cast<std::size_t>(u)] = rotation(c.nodes[static_cast<std::size_t>(u)]);
      solver_.prepare(k, r.data());
      const ContactStatus st = solver_.factor(k);
      if (st != ContactStatus::kOk) return st;
      solver_.solve(b.data(), mu.data());
      solver_.node_forces(k, mu.data(), lambda.data());
      return ContactStatus::kOk;
    };
    // Fixed point: rotations from the rest-frame response u~ = G R^T lambda of every visible node.
    double change = 1;
    if (given != nullptr) {
      rot_.update_all(*given, 60);
      change = 0;
    }
    for (int it = 0; it < 30 && change > 1e-7; ++it) {
      if (one_pass() != ContactStatus::kOk) throw surgsim::core::Error(c.name + ": corotational factorization failed");
      for (int u = 0; u < n; ++u) rest_lambda[static_cast<std::size_t>(u)] = rotation(c.nodes[static_cast<std::size_t>(u)]).transpose() * lambda[static_cast<std::size_t>(u)];
      visual_.displacements(c.nodes.data(), rest_lambda.data(), n, uv);
      for (int row = 0; row < vis.row_count(); ++row) ut_.row(vis.row_nodes[static_cast<std::size_t>(row)]) = uv.segment<3>(3 * row).transpose();
      change = 0;
      for (int node : organ_.visible) {
        const Eigen::Quaterniond before = rot_.quaternion(node);
        rot_.update(node, disp, 30);
        change = std::max(change, before.angularDistance(rot_.quaternion(node)));
      }
    }
    Outcome out;
    one_pass();
    for (int u = 0; u < n; ++u) out.force -= lambda[static_cast<std::size_t>(u)];
    out.u.resize(3 * vis.row_count());
    for (int row = 0; row < vis.row_count(); ++row) {
      const int node = vis.row_nodes[static_cast<std::size_t>(row)];
      const Eigen::Vector3d x0 = organ_.mesh.nodes.row(node).transpose();
      out.u.segment<3>(3 * row) = c.base.apply(x0) - x0 + rotation(node) * ut_.row(node).transpose();
    }
    // The tick: the contact nodes' rotations (warm, from the field), the warped prepare, factor, solve.
    for (int rep = 0; rep < repeats; ++rep) {
      const auto t0 = Clock::now();
      for (int u = 0; u < n; ++u) rot_.update(c.nodes[static_cast<std::size_t>(u)], disp);
      one_pass();
      out.tick_us.push_back(us_since(t0));
    }
    return out;
  }

 private:
  const Organ& organ_;
  const Tensors& tensors_;
  PatchSolver solver_;
  Superposition visual_;
  NodeRotations rot_;
  Eigen::MatrixX3d ut_;
};

// ---- multirate (nonlinear/multirate.h) ----

// The contact targets of a case at fraction s of its motion, in the fixed set's frame: a press straight from rest
// (s u*), a lift along the circle (the grasp turned by s times the angle about the hinge), the rigid case 0 (the
// tracker works in the frame of its fixed set, so the organ's rigid motion imposes nothing there).
ContactTargets targets_at(const Case& c, const Organ& o, double s) {
  ContactTargets t;
  t.count = static_cast<int>(c.nodes.size());
  const Eigen::Matrix3d q = Eigen::AngleAxisd(s * c.angle * kPi / 180, Eigen::Vector3d::UnitY()).toRotationMatrix();
  for (int k = 0; k < t.count; ++k) {
    const int node = c.nodes[static_cast<std::size_t>(k)];
    const Eigen::Vector3d x0 = o.mesh.nodes.row(node).transpose();
    t.nodes[static_cast<std::size_t>(k)] = node;
    if (c.rigid)
      t.u[static_cast<std::size_t>(k)] = c.base.r.transpose() * (x0 + c.u_star[static_cast<std::size_t>(k)] - c.base.t) - x0;
    else if (c.lift)
      t.u[static_cast<std::size_t>(k)] = (q - Eigen::Matrix3d::Identity()) * (x0 - c.hinge);
    else
      t.u[static_cast<std::size_t>(k)] = s * c.u_star[static_cast<std::size_t>(k)];
  }
  return t;
}

std::vector<Contact> contacts_of(const ContactTargets& t) {
  std::vector<Contact> out;
  for (int k = 0; k < t.count; ++k) out.push_back({t.nodes[static_cast<std::size_t>(k)], t.u[static_cast<std::size_t>(k)]});
  return out;
}

Eigen::Vector3d tool_force(const TrackerSnapshot& s) {
  Eigen::Vector3d f = Eigen::Vector3d::Zero();
  for (int k = 0; k < s.count; ++k) f -= s.reaction[static_cast<std::size_t>(k)];
  return f;
}

// The Newton quasi-static force along a case's path at s = k / samples, k = 0 .. samples: a continuation of the
// tracker converged at every sample (forces only). NaN where it did not converge.
std::vector<Eigen::Vector3d> reference_path(const Case& c, const Organ& o, const HyperelasticSolver& solver, int samples) {
  MultirateOptions mo;
  mo.iterations_per_cycle = 25;
  mo.contact_stiffness = false;
  NonlinearTracker ref(solver, {}, mo);
  std::vector<Eigen::Vector3d> out;
  for (int k = 0; k <= samples; ++k) {
    const ContactTargets t = targets_at(c, o, static_cast<double>(k) / samples);
    bool ok = false;
    for (int tries = 0; tries < 20 && !ok; ++tries) ok = ref.cycle(t).converged;
    ref.snapshots().take();
    out.push_back(ok ? tool_force(ref.snapshots().front()) : Eigen::Vector3d::Constant(std::nan("")));
  }
  return out;
}

// One motion of the tool from rest to the case's target in `duration_s`, the haptic loop at 1 kHz and the slow side
// emulated in step: a cycle starts when the previous one ends, reads the targets of the tick it starts in, and its
// snapshot becomes visible to the loop `cycle_ms` later (the cycle's own measured wall time, or `fixed_cycle_ms`).
// Errors at the ticks whose s hits a reference sample: |F - F_ref(s)| / max(|F_ref(s)|, 5 % |F_ref(1)|).
struct MotionResult {
  std::vector<double> error, cycle_ms, iteration_ms, assemble_ms, factor_ms, solve_ms, tick_us;
  int ticks = 0, fallback_ticks = 0;
  int predictor_halvings = 0, failures = 0;  // of the slow cycles
  double worst_residual = 0;                 // relative, of a published state
};
MotionResult run_motion(const Case& c, const Organ& o, NonlinearTracker& tracker, Superposition& linear,
                        double duration_s, const std::vector<Eigen::Vector3d>& ref, double fixed_cycle_ms,
                        bool predict, std::FILE* trace = nullptr) {
  MotionResult out;
  const int ticks = static_cast<int>(std::lround(duration_s * 1000));
  double last_d = 0;  // ms, the last slow cycle's time (the prediction horizon)
  const int samples = static_cast<int>(ref.size()) - 1;
  const double floor = 0.05 * ref.back().norm();
  tracker.reset();
  TrackerSnapshot pending = tracker.snapshots().front(), visible = pending;
  visible.valid = pending.valid = false;
  bool has_pending = false;
  double pending_at = 0, next_start = 0;
  ContactSolution sol;
  for (int k = 0; k <= ticks; ++k) {
    while (next_start <= k) {
      if (has_pending) std::swap(visible, pending);  // published when this cycle starts
      // The targets the haptic side hands over at the tick the cycle starts: the tool's position, or with `predict`
      // its position extrapolated by the last cycle's time from its velocity over the last 10 ticks (what the
      // haptic side can know), so that the snapshot is about where the tool is when it becomes visible.
      const int k0 = static_cast<int>(std::floor(next_start));
      ContactTargets t = targets_at(c, o, static_cast<double>(std::min(k0, ticks)) / ticks);
      if (predict && k0 > 0) {
        const int kb = std::max(0, k0 - 10);
        const ContactTargets back = targets_at(c, o, static_cast<double>(std::min(kb, ticks)) / ticks);
        for (int q = 0; q < t.count; ++q)
          t.u[static_cast<std::size_t>(q)] += (t.u[static_cast<std::size_t>(q)] - back.u[static_cast<std::size_t>(q)]) * (last_d / (k0 - kb));
      }
      const TrackerCycle cy = tracker.cycle(t);
      const double d = fixed_cycle_ms > 0 ? fixed_cycle_ms : cy.total_ms;
      last_d = d;
      out.cycle_ms.push_back(cy.total_ms);
      out.predictor_halvings += cy.predictor_halvings;
      out.failures += cy.failure.empty() ? 0 : 1;
      out.worst_residual = std::max(out.worst_residual, cy.residual);
      if (trace) {
        tracker.snapshots().take();
        const TrackerSnapshot& sn = tracker.snapshots().front();
        double lag = 0, tgt = 0;
        for (int q = 0; q < t.count; ++q) {
          lag = std::max(lag, (t.u[static_cast<std::size_t>(q)] - sn.u[static_cast<std::size_t>(q)]).norm());
          tgt = std::max(tgt, t.u[static_cast<std::size_t>(q)].norm());
        }
        std::fprintf(trace, "cycle %s T %g start %d visible %g ms %.2f it %d conv %d res %.3e halv %d corr %d ldlt %d "
                            "rejected %d published %d lag_mm %.2f target_mm %.2f F %.4f |S| %.4g fail '%s'\n",
                     c.name.c_str(), duration_s, k0, next_start + d, cy.total_ms, cy.iterations, cy.converged ? 1 : 0,
                     cy.residual, cy.predictor_halvings, cy.corrections, cy.ldlt_fallback ? 1 : 0, cy.step_rejected ? 1 : 0, cy.published ? 1 : 0, 1e3 * lag, 1e3 * tgt,
                     tool_force(sn).norm(), sn.stiffness.topLeftCorner(3 * sn.count, 3 * sn.count).norm(), cy.failure.c_str());
      }
      if (cy.iterations > 0) {
        out.iteration_ms.push_back((cy.assemble_ms + cy.factor_ms + cy.solve_ms) / cy.iterations);
        out.assemble_ms.push_back(cy.assemble_ms / cy.iterations);
        out.factor_ms.push_back(cy.factor_ms / cy.iterations);
        out.solve_ms.push_back(cy.solve_ms / cy.iterations);
      }
      tracker.snapshots().take();
      pending = tracker.snapshots().front();
      has_pending = true;
      pending_at = next_start + d;
      next_start += std::max(d, 1e-3);
    }
    if (has_pending && pending_at <= k) {
      std::swap(visible, pending);
      has_pending = false;
    }
    const double s = static_cast<double>(k) / ticks;
    const std::vector<Contact> contacts = contacts_of(targets_at(c, o, s));
    const auto t0 = Clock::now();
    bool ok = local_contact_forces(visible, contacts.data(), static_cast<int>(contacts.size()),
                                   tracker.options().max_extrapolation, sol);
    if (!ok) linear.solve(contacts.data(), static_cast<int>(contacts.size()), sol);
    out.tick_us.push_back(us_since(t0));
    out.fallback_ticks += ok ? 0 : 1;
    ++out.ticks;
    if ((static_cast<long>(k) * samples) % ticks == 0) {
      const Eigen::Vector3d& fr = ref[static_cast<std::size_t>(static_cast<long>(k) * samples / ticks)];
      if (fr.allFinite()) out.error.push_back((sol.tool_force - fr).norm() / std::max(fr.norm(), floor));
      if (trace) {
        double du = 0;
        for (int q = 0; q < visible.count && ok; ++q)
          du = std::max(du, (contacts[static_cast<std::size_t>(q)].displacement - visible.u[static_cast<std::size_t>(q)]).norm());
        std::fprintf(trace, "tick %s T %g k %d snap %llu ok %d du_mm %.2f F %.4f %.4f %.4f Fref %.4f %.4f %.4f err %.4f\n",
                     c.name.c_str(), duration_s, k, static_cast<unsigned long long>(visible.cycle), ok ? 1 : 0, 1e3 * du,
                     sol.tool_force.x(), sol.tool_force.y(), sol.tool_force.z(), fr.x(), fr.y(), fr.z(),
                     (sol.tool_force - fr).norm() / std::max(fr.norm(), floor));
      }
    }
  }
  return out;
}

std::string sci(double v) {
  if (!std::isfinite(v)) return "nan";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return buf;
}

}  // namespace

int main(int argc, char** argv) {
  std::string scene_name = "liver", out_dir, cache;
  int nodes = 1500, repeats = 300, motion_samples = 1000, iterations_per_cycle = 1, corrections_per_cycle = 10;
  bool quick = false, slow_cycle_only = false, predict = true;
  std::vector<double> durations{1.0, 0.5};
  double fixed_cycle_ms = 0, max_step_mm = 5, move_tolerance = 1e-2;
  std::vector<std::string> only;
  std::string trace_path;
  CLI::App app{
      "large_deformation_bench: the liver at large deformation: linear, quasi non-linear "
      "(cylinder and organ curves), corotational and corotational with organ curves against a neo-Hookean "
      "Newton reference, indentation 5-30 %, a lobe lifted 45 and 90 degrees, a rigid 90-degree turn; "
      "tick and visual timings. Tables on stdout, DIR/liver_large_deformation.csv with --out."};
  app.add_option("--out", out_dir, "Write liver_large_deformation.csv to this folder (created if missing)");
  app.add_option("--cache", cache, "Mesh and organ-curve cache folder (default: $SURGSIM_CACHE_DIR, else ~/.cache/surgsim)");
  app.add_option("--scene", scene_name, "Scene (name or YAML): material, clamp, cylinder curves")->capture_default_str();
  app.add_option("--nodes", nodes, "Target node count of the liver")->capture_default_str();
  app.add_option("--repeats", repeats, "Timed repeats per case and method")->capture_default_str();
  app.add_flag("--quick", quick, "Short run: fewer timing repeats, organ curves from 3 depths, 100 motion samples");
  app.add_option("--durations", durations, "multirate: durations of the tool's motion from rest to each target, s")
      ->capture_default_str();
  app.add_option("--motion-samples", motion_samples,
                 "multirate: Newton reference samples along each path (the error is taken at the ticks that hit one)")
      ->capture_default_str()->check(CLI::Range(10, 100000));
  app.add_option("--iterations-per-cycle", iterations_per_cycle, "multirate: Newton iterations per slow cycle")
      ->capture_default_str()->check(CLI::Range(1, 50));
  app.add_option("--corrections-per-cycle", corrections_per_cycle,
                 "multirate: modified Newton corrections after each iteration, on its factor")
      ->capture_default_str()->check(CLI::Range(0, 50));
  app.add_option("--max-step-mm", max_step_mm, "multirate: largest move of a contact node per predictor, mm")
      ->capture_default_str()->check(CLI::PositiveNumber);
  app.add_option("--move-tolerance", move_tolerance,
                 "multirate: relative residual a state must reach before the contact nodes move on")
      ->capture_default_str()->check(CLI::PositiveNumber);
  app.add_option("--slow-cycle-ms", fixed_cycle_ms,
                 "multirate: emulate every slow cycle as taking this long (0: each cycle's measured wall time)")
      ->capture_default_str();
  app.add_flag("--predict,!--no-predict", predict,
               "multirate: the haptic side hands the slow side the tool's position extrapolated by the last slow "
               "cycle's time (its velocity over 10 ticks; the default), or (--no-predict) the current one");
  app.add_option("--trace", trace_path,
                 "multirate: write every slow cycle and every reference tick of the motions to this text file");
  app.add_option("--only", only, "Only these cases (a study; rigid_90's error needs indent_10 in the list)");
  app.add_flag("--slow-cycle-only", slow_cycle_only,
               "Only time the multirate slow cycle (one Newton iteration: tangent, factor, contact solves) on this "
               "liver during a 1 s press to 20 % and lift to 90 degrees; no reference, no other method");
  CLI11_PARSE(app, argc, argv);
  if (quick) {
    repeats = std::min(repeats, 60);
    motion_samples = std::min(motion_samples, 100);
  }
  for (double d : durations)
    if (!(d >= 0.01 && d <= 100)) {
      std::cerr << "large_deformation_bench: --durations " << d << " is out of [0.01, 100] s\n";
      return 2;
    }

  try {
    const auto start = Clock::now();
    const Scene scene = load_scene(resolve_scene_path(scene_name));
    if (cache.empty()) cache = default_cache_dir();
    if (!out_dir.empty()) bench::make_dirs(out_dir);
    const auto organ = make_organ(scene, nodes, cache, false);
    const Organ& o = *organ;
    progress("liver of " + std::to_string(o.mesh.nodes.rows()) + " nodes: precompute");
    PrecomputeOptions popts;
    popts.memory_limit_mb = 0;
    const Tensors tensors = precompute_tensors(*o.model, o.contacts, o.rows, popts);


    // ---- the cases and their references ----
    std::vector<Case> cases;
    const std::vector<int> punch = punch_nodes(o);
    for (int p = 5; p <= 30; p += 5) {
      Case c;
      c.name = "indent_" + std::to_string(p);
      c.depth_percent = p;
      c.nodes = punch;
      c.u_star.assign(punch.size(), Eigen::Vector3d(0, 0, -p / 100.0 * o.height));
      cases.push_back(c);
    }
    const std::vector<int> grasp = punch_nodes(o, Eigen::Vector2d(-0.100, 0.010), 0.012);
    const Eigen::Vector3d hinge(-0.070, 0.010, -0.010);
    for (double deg : {45.0, 90.0}) {
      Case c;
      c.name = "lift_" + std::to_string(static_cast<int>(deg));
      c.angle = deg;
      c.lift = true;
      c.hinge = hinge;
      c.nodes = grasp;
      const Eigen::Matrix3d q = Eigen::AngleAxisd(deg * kPi / 180, Eigen::Vector3d::UnitY()).toRotationMatrix();
      for (int k : grasp) {
        const Eigen::Vector3d x0 = o.mesh.nodes.row(k).transpose();
        c.u_star.push_back((q - Eigen::Matrix3d::Identity()) * (x0 - hinge));
      }
      cases.push_back(c);
    }
    {
      Case c;
      c.name = "rigid_90";
      c.angle = 90;
      c.rigid = true;
      c.nodes = punch;
      c.base.r = Eigen::AngleAxisd(kPi / 2, Eigen::Vector3d(1, 1, 1).normalized()).toRotationMatrix();
      c.base.t = Eigen::Vector3d(0.02, -0.03, 0.05);
      for (int k : punch) {
        const Eigen::Vector3d x0 = o.mesh.nodes.row(k).transpose();
        c.u_star.push_back(c.base.apply(x0) - x0);
      }
      // The fixed set's frame as the nodes would estimate it: shape matching of the fixed nodes' displacements.
      Eigen::MatrixX3d u_all(o.mesh.nodes.rows(), 3);
      std::vector<int> fixed_nodes;
      for (Eigen::Index n = 0; n < o.mesh.nodes.rows(); ++n) {
        const Eigen::Vector3d x0 = o.mesh.nodes.row(n).transpose();
        u_all.row(n) = (c.base.apply(x0) - x0).transpose();
        if (o.fixed.node_touched(static_cast<int>(n))) fixed_nodes.push_back(static_cast<int>(n));
      }
      c.base = fit_rigid_frame(o.mesh.nodes, fixed_nodes, u_all);
      c.u_ref = visible_part(o, u_all);
      cases.push_back(c);
    }
    if (!only.empty())
      cases.erase(std::remove_if(cases.begin(), cases.end(),
                                 [&](const Case& c) { return std::find(only.begin(), only.end(), c.name) == only.end(); }),
                  cases.end());
    if (punch.empty() || grasp.empty()) throw surgsim::core::Error("no punch or grasp nodes on this mesh");
    if (static_cast<int>(std::max(punch.size(), grasp.size())) > kMaxContacts)
      throw surgsim::core::Error("more than kMaxContacts constrained nodes");

    // The multirate slow side on this liver: a Newton iteration's cost decides the snapshot rate.
    const HyperelasticSolver newton(*o.model);
    MultirateOptions mopts;
    mopts.iterations_per_cycle = iterations_per_cycle;
    mopts.corrections_per_cycle = corrections_per_cycle;
    mopts.max_step = max_step_mm * 1e-3;
    mopts.move_tolerance = move_tolerance;
    NonlinearTracker tracker(newton, o.visible, mopts);
    std::unique_ptr<std::FILE, int (*)(std::FILE*)> trace(nullptr, &std::fclose);
    if (!trace_path.empty()) {
      trace.reset(std::fopen(trace_path.c_str(), "w"));
      if (!trace)
        throw surgsim::core::Error("--trace " + trace_path + ": cannot write the file (does its folder exist?)");
    }
    Superposition linear_fallback(tensors, "haptic");
    const auto print_slow_cycle = [&](const char* what, const MotionResult& mr) {
      std::printf("%-10s %-22s | %9.2f %9.2f | %9.2f %9.2f | %6zu | %6d / %d\n", what,
                  ("assemble " + sci(bench::percentile(mr.assemble_ms, 0.5)) + ", factor " +
                   sci(bench::percentile(mr.factor_ms, 0.5)) + ", solve " + sci(bench::percentile(mr.solve_ms, 0.5))).c_str(), bench::percentile(mr.iteration_ms, 0.5),
                  bench::percentile(mr.iteration_ms, 0.99), bench::percentile(mr.cycle_ms, 0.5),
                  bench::percentile(mr.cycle_ms, 0.99), mr.cycle_ms.size(), mr.fallback_ticks, mr.ticks);
    };
    const char* slow_header = "%-10s %-22s | %9s %9s | %9s %9s | %6s | %s\n";
    if (slow_cycle_only) {
      std::printf("Liver %d nodes (%d dofs), %d visible; multirate slow cycle, %d Newton iteration(s) per cycle, tool "
                  "moved in 1 s (ms)\n", static_cast<int>(o.mesh.nodes.rows()), 3 * static_cast<int>(o.mesh.nodes.rows()),
                  static_cast<int>(o.visible.size()), iterations_per_cycle);
      std::printf(slow_header, "case", "", "iter p50", "iter p99", "cycle p50", "cycle p99", "cycles", "fallback ticks");
      for (const Case& c : cases) {
        if (c.name != "indent_20" && c.name != "lift_90") continue;
        const std::vector<Eigen::Vector3d> no_ref(2, Eigen::Vector3d::Constant(std::nan("")));
        std::printf("%s: %zu contact nodes\n", c.name.c_str(), c.nodes.size());
        print_slow_cycle(c.name.c_str(), run_motion(c, o, tracker, linear_fallback, 1.0, no_ref, fixed_cycle_ms, predict));
      }
      std::printf("\nTotal %.1f s\n", us_since(start) * 1e-6);
      return 0;
    }

    // The laws: the scene's cylinder curves, and the organ's own (cached next to the tensors).
    const NonlinearLaw cylinder = load_nonlinear_law(scene.nonlinear, scene.material);
    OrganCurveSettings ocs;
    if (quick) ocs.depths = {0.1, 0.2, 0.3};
    const std::uint64_t tensor_key = liver_tensor_setup(scene.material, scene.fixed, o.mesh, cache, scene.file).key.combined();
    OrganCurvesOutcome oc_outcome;
    const auto tc0 = Clock::now();
    const OrganCurves curves = load_or_compute_organ_curves(*o.model, ocs, tensor_key, cache, &std::cerr, &oc_outcome);
    const double curves_s = us_since(tc0) * 1e-6;
    FitReport q_rep;
    const NonlinearLaw organ_law = fit_organ_law(curves, o.mesh, o.fixed, ocs, &q_rep);
    // The organ law's surface field, leave-one-site-out; the punch below is not a fit site (its distance to the
    // nearest one is printed).
    const OrganLawValidation cv = validate_organ_law(curves, ocs);
    double nearest_site = 1e9;
    for (const auto& s : cv.sites) nearest_site = std::min(nearest_site, (Eigen::Vector2d(s.site_x, s.site_y) - kPunchCentre).norm());
    std::printf("Liver %d nodes, %d visible; organ curves %s in %.1f s (%zu Newton indentations at %zu sites over the "
                "free top, the nearest %.1f cm from the punch's centre), Q fit max residual %.2e, P left out\n"
                "Organ surface field, leave-one-site-out force error over every site and depth: mean %.2f %%, worst "
                "%.1f %% (in sample %.2f %%)\n",
                static_cast<int>(o.mesh.nodes.rows()), static_cast<int>(o.visible.size()),
                oc_outcome == OrganCurvesOutcome::kLoaded ? "loaded" : "computed", curves_s, curves.samples.size(),
                cv.sites.size(), 100 * nearest_site, q_rep.max_residual, 100 * cv.mean, 100 * cv.worst, 100 * cv.fitted_worst);
    for (const auto& s : cv.sites)
      std::printf("  site (%6.3f, %6.3f) %2d nodes: held out %5.1f %%, one Q for the organ %5.1f %%\n", s.site_x, s.site_y,
                  s.nodes, 100 * s.worst, 100 * s.q_worst);

    double f_indent10 = 0;
    for (Case& c : cases) {
      if (c.rigid) continue;
      std::vector<ImposedDisplacement> imposed;
      double largest = 0;
      for (std::size_t i = 0; i < c.nodes.size(); ++i) {
        imposed.push_back({c.nodes[i], c.u_star[i], 7});
        largest = std::max(largest, c.u_star[i].norm());
      }
      HyperelasticOptions opts;
      opts.load_steps = std::max(2, static_cast<int>(std::ceil(largest / 0.002)));
      progress(c.name + ": Newton, " + std::to_string(opts.load_steps) + " increments");
      const HyperelasticSolution ref = HyperelasticSolver(*o.model, opts).solve(imposed);
      c.converged = ref.converged();
      if (!c.converged) progress(c.name + ": Newton did not converge: " + ref.message);
      c.f_ref = -ref.total_reaction;
      c.u_ref = visible_part(o, ref.displacement);
      c.newton_u = ref.displacement;
      if (c.name == "indent_10") f_indent10 = c.f_ref.norm();
    }

    // ---- the methods ----
    Superposition haptic(tensors, "haptic"), visual(tensors, "visual");
    const TensorBlock& vis = visual.block();
    Corotational corot(o, tensors);
    bench::CsvOut csv(out_dir, "liver_large_deformation", "case,method,force_rel_error,disp_rel_error,tick_us_p99");
    struct MotionRow {
      std::string name;
      double duration_s;
      MotionResult result;
    };
    std::vector<MotionRow> motion_rows;
    std::printf("\n%-10s %-18s | %12s %12s | %10s | %9s\n", "case", "method", "force err", "disp err", "tick p99 us",
                "F N");
    for (const Case& c : cases) {
      const int m = static_cast<int>(c.nodes.size());
      std::vector<Contact> contacts;
      for (int i = 0; i < m; ++i) contacts.push_back({c.nodes[static_cast<std::size_t>(i)], c.u_star[static_cast<std::size_t>(i)]});
      std::map<std::string, Outcome> res;
      // linear and the two quasi laws
      ContactSolution sol;
      for (const char* method : {"linear", "quasi_cylinder", "quasi_organ"}) {
        const NonlinearLaw* law = std::string(method) == "quasi_cylinder" ? &cylinder
                                  : std::string(method) == "quasi_organ" ? &organ_law : nullptr;
        Outcome out;
        for (int rep = 0; rep < repeats; ++rep) {
          const auto t0 = Clock::now();
          haptic.solve(contacts.data(), m, sol);
          Eigen::Vector3d f = sol.tool_force, dir;
          if (law && constraint_direction(sol.displacement.data(), sol.count, dir))
            law->apply_force(f, dir, sol.nodes.data(), sol.displacement.data(), sol.count, f);
          out.tick_us.push_back(us_since(t0));
        }
        if (haptic.solve(contacts.data(), m, sol) != ContactStatus::kOk)
          throw surgsim::core::Error(c.name + ": G_CC solve failed");
        out.force = sol.tool_force;
        out.u.resize(3 * vis.row_count());
        visual.displacements(sol.nodes.data(), sol.lambda.data(), sol.count, out.u);
        if (law) apply_quasi(*law, sol.displacement.data(), sol.count, sol.nodes.data(), vis, out.force, out.u);
        res[method] = std::move(out);
      }
      res["corotational"] = corot.solve(c, repeats);
      {
        Outcome co = res["corotational"];
        // The organ law on the corotational result: Q along the mean imposed displacement, P on the visible rows.
        std::vector<Eigen::Vector3d> imposed = c.u_star;
        apply_quasi(organ_law, imposed.data(), m, c.nodes.data(), vis, co.force, co.u);
        res["corotational_organ"] = std::move(co);
      }
      {
        // multirate: the tool moved from rest to the target in each duration (the motion table), then, after the
        // first motion, held there until the tracker converged: the static error (Newton's tolerance by construction).
        const std::vector<Eigen::Vector3d> path =
            c.rigid ? std::vector<Eigen::Vector3d>{} : reference_path(c, o, newton, motion_samples);
        if (!c.rigid && path.back().allFinite() && c.converged)
          progress(c.name + ": reference path end against Newton's solve: " +
                   sci((path.back() - c.f_ref).norm() / c.f_ref.norm()));
        if (c.rigid)
          tracker.reset();
        else
          motion_rows.push_back({c.name, durations[0], run_motion(c, o, tracker, linear_fallback, durations[0], path, fixed_cycle_ms, predict, trace.get())});
        const ContactTargets target = targets_at(c, o, 1.0);
        int hold = 0;
        while (hold < 200 && !tracker.cycle(target).converged) ++hold;
        tracker.snapshots().take();
        const TrackerSnapshot& snap = tracker.snapshots().front();
        const std::vector<Contact> local = contacts_of(target);
        Outcome mo;
        ContactSolution ms;
        for (int rep = 0; rep < repeats; ++rep) {
          const auto t0 = Clock::now();
          if (!local_contact_forces(snap, local.data(), m, mopts.max_extrapolation, ms)) linear_fallback.solve(local.data(), m, ms);
          mo.tick_us.push_back(us_since(t0));
        }
        if (!local_contact_forces(snap, local.data(), m, mopts.max_extrapolation, ms))
          progress(c.name + ": multirate: no valid snapshot after " + std::to_string(hold) + " held cycles");
        mo.force = c.base.r * ms.tool_force;
        mo.u.resize(3 * static_cast<Eigen::Index>(o.visible.size()));
        for (std::size_t r = 0; r < o.visible.size(); ++r) {
          const Eigen::Vector3d x0 = o.mesh.nodes.row(o.visible[r]).transpose();
          mo.u.segment<3>(3 * static_cast<Eigen::Index>(r)) = c.base.apply(x0 + snap.surface.segment<3>(3 * static_cast<Eigen::Index>(r))) - x0;
        }
        res["multirate"] = std::move(mo);
        for (std::size_t k = 1; k < durations.size() && !c.rigid; ++k)
          motion_rows.push_back({c.name, durations[k], run_motion(c, o, tracker, linear_fallback, durations[k], path, fixed_cycle_ms, predict, trace.get())});
      }
      for (const char* method : {"linear", "quasi_cylinder", "quasi_organ", "corotational", "corotational_organ", "multirate"}) {
        const Outcome& r = res[method];
        double fe, de;
        if (c.rigid) {
          fe = rel(r.force.norm(), f_indent10);
          de = rel((r.u - c.u_ref).norm(), c.u_ref.norm());
        } else if (!c.converged) {
          fe = de = std::nan("");
        } else {
          fe = rel((r.force - c.f_ref).norm(), c.f_ref.norm());
          de = rel((r.u - c.u_ref).norm(), c.u_ref.norm());
        }
        const double p99 = bench::percentile(r.tick_us, 0.99);
        std::printf("%-10s %-18s | %12s %12s | %10.2f | %9.4f%s\n", c.name.c_str(), method, sci(fe).c_str(),
                    sci(de).c_str(), p99, r.force.norm(), c.rigid ? "  (force err: / F_Newton(indent_10))" : "");
        csv.row("%s,%s,%s,%s,%.6g", c.name.c_str(), method, sci(fe).c_str(), sci(de).c_str(), p99);
      }
      if (!c.rigid) {
        std::printf("%-10s %-18s | %12s %12s | %10s | %9.4f\n", c.name.c_str(), "newton", "-", "-", "-", c.f_ref.norm());
        // Diagnostic (stdout only): the corotational solve with the Newton field's own rotations.
        const Outcome d = corot.solve(c, 1, &c.newton_u);
        std::printf("%-10s %-18s | %12s %12s | %10s | %9.4f  (diagnostic: rotations of the Newton field)\n",
                    c.name.c_str(), "corot_true_rot", sci(rel((d.force - c.f_ref).norm(), c.f_ref.norm())).c_str(), "-",
                    "-", d.force.norm());
      }
    }

    // ---- multirate in motion ----
    bench::CsvOut motion_csv(out_dir, "liver_large_deformation_motion",
                             "case,method,duration_s,force_rel_error_p99,force_rel_error_max,slow_cycle_ms_p50,slow_cycle_ms_p99");
    std::printf("\nmultirate in motion: the tool from rest to the target (straight press, circular lift) in the given "
                "time, the 1 kHz loop on the newest snapshot the slow side has published (%d Newton iteration(s) and up "
                "to %d corrections a cycle, %s, %s); force error against the Newton quasi-static force at the same tool position, "
                "|F - F_ref| / max(|F_ref|, 5 %% |F_ref(end)|), at the ticks hitting the %d reference samples\n",
                iterations_per_cycle, corrections_per_cycle, fixed_cycle_ms > 0 ? "cycles emulated at --slow-cycle-ms" : "each cycle visible after its measured wall time",
                predict ? "targets predicted by the last cycle's time from the tool's velocity" : "targets not predicted",
                motion_samples);
    std::printf("%-10s %6s | %10s %10s | %9s %9s %9s | %6s | %8s | %-11s | %s\n", "case", "T s", "F err p99", "F err max",
                "iter p50", "cycle p50", "cycle p99", "cycles", "tick p99", "fallback", "predictor cuts, failed cycles, worst residual");
    std::vector<double> all_iter, all_cycle;
    for (const MotionRow& r : motion_rows) {
      const MotionResult& mr = r.result;
      const double p99 = mr.error.empty() ? std::nan("") : bench::percentile(mr.error, 0.99);
      const double mx = mr.error.empty() ? std::nan("") : *std::max_element(mr.error.begin(), mr.error.end());
      all_iter.insert(all_iter.end(), mr.iteration_ms.begin(), mr.iteration_ms.end());
      all_cycle.insert(all_cycle.end(), mr.cycle_ms.begin(), mr.cycle_ms.end());
      std::printf("%-10s %6.2f | %10s %10s | %9.2f %9.2f %9.2f | %6zu | %8.2f | %4d / %-4d | %d, %d, %s\n", r.name.c_str(),
                  r.duration_s, sci(p99).c_str(), sci(mx).c_str(), bench::percentile(mr.iteration_ms, 0.5),
                  bench::percentile(mr.cycle_ms, 0.5), bench::percentile(mr.cycle_ms, 0.99), mr.cycle_ms.size(),
                  bench::percentile(mr.tick_us, 0.99), mr.fallback_ticks, mr.ticks, mr.predictor_halvings, mr.failures,
                  sci(mr.worst_residual).c_str());
      motion_csv.row("%s,multirate,%g,%s,%s,%.6g,%.6g", r.name.c_str(), r.duration_s, sci(p99).c_str(), sci(mx).c_str(),
                     bench::percentile(mr.cycle_ms, 0.5), bench::percentile(mr.cycle_ms, 0.99));
    }
    if (!all_cycle.empty())
      std::printf("slow cycle over all motions: one Newton iteration (tangent, internal force, factor, %s) p50 %.2f p99 "
                  "%.2f ms; cycle p50 %.2f p99 %.2f ms, i.e. %.0f snapshots/s at p50\n", "contact solves",
                  bench::percentile(all_iter, 0.5), bench::percentile(all_iter, 0.99), bench::percentile(all_cycle, 0.5),
                  bench::percentile(all_cycle, 0.99), 1000 / bench::percentile(all_cycle, 0.5));

    // ---- the haptic tick and the visual frame, linear against corotational ----
    std::printf(
        "\nHaptic tick (ToolContacts, patch model, one instrument pressing 8 mm at (0.03, 0); us, %d ticks "
        "after 50 warm)\n",
        10 * repeats);
    std::printf("%-14s | %8s %8s %8s | %6s\n", "deformation", "p50", "p99", "max", "nodes");
    for (LiverDeformation d : {LiverDeformation::kLinear, LiverDeformation::kCorotational}) {
      const SurfaceMesh surface = boundary_surface(o.mesh);
      ToolSpec spec = scene.tools[0];
      spec.shaft_points = 1;
      ToolContacts lc(o.mesh, surface, tensors, std::vector<ToolSpec>{spec}, nullptr, d);
      const double top = [&] {
        double z = -1;
        for (int k : punch) z = std::max(z, o.mesh.nodes(k, 2));
        return z;
      }();
      std::vector<double> t;
      for (int k = 0; k < 50 + 10 * repeats; ++k) {
        const double depth = std::min(0.008, 0.0004 * k) + 0.0005 * std::sin(0.05 * k);
        ToolGeometry g{};
        g.direction = {0, 0, -1};
        g.tip = Eigen::Vector3d(kPunchCentre.x(), kPunchCentre.y(), top + 0.002 - depth);
        g.trocar = g.tip + Eigen::Vector3d(0, 0, 0.15);
        g.jaw_normal = {1, 0, 0};
        g.jaw_tips = {g.tip, g.tip};
        g.point_count = 1;
        g.points[0] = g.tip;
        ContactTick tick;
        const auto t0 = Clock::now();
        lc.step(g, 0.5, tick);
        if (k >= 50) t.push_back(us_since(t0));
        if (k % 5 == 0) lc.refresh_rotations();  // the 200 Hz thread, here between ticks
      }
      std::printf("%-14s | %8.2f %8.2f %8.2f | %6d\n", to_string(d), bench::percentile(t, 0.5),
                  bench::percentile(t, 0.99), *std::max_element(t.begin(), t.end()), lc.solution().count);
    }
    {
      // Exactly 10 contact nodes (node_bench's count), 3 rows each: the G_CC solve against the warped patch solve
      // with the contact nodes' rotations.
      std::vector<int> ten(punch.begin(), punch.begin() + std::min<std::size_t>(10, punch.size()));
      Case c;
      c.name = "ten";
      c.nodes = ten;
      c.u_star.assign(ten.size(), Eigen::Vector3d(0, 0, -0.005));
      const Outcome co = corot.solve(c, 10 * repeats);
      std::vector<Contact> contacts;
      for (int k : ten) contacts.push_back({k, Eigen::Vector3d(0, 0, -0.005)});
      ContactSolution sol;
      std::vector<double> tl;
      for (int rep = 0; rep < 10 * repeats; ++rep) {
        const auto t0 = Clock::now();
        haptic.solve(contacts.data(), static_cast<int>(contacts.size()), sol);
        tl.push_back(us_since(t0));
      }
      // multirate: MultirateForce::evaluate (take the newest snapshot, f_c + S du) on a converged snapshot, the tool
      // wobbling by up to 0.5 mm about it.
      tracker.reset();
      ContactTargets tt;
      tt.count = static_cast<int>(ten.size());
      for (std::size_t k = 0; k < ten.size(); ++k) {
        tt.nodes[k] = ten[k];
        tt.u[k] = Eigen::Vector3d(0, 0, -0.005);
      }
      for (int k = 0; k < 50 && !tracker.cycle(tt).converged; ++k) {
      }
      MultirateForce fast(tracker.snapshots(), linear_fallback, mopts.max_extrapolation);
      std::vector<double> tm;
      int nonlinear = 0;
      for (int rep = 0; rep < 10 * repeats; ++rep) {
        for (auto& x : contacts) x.displacement.z() = -0.005 + 0.0005 * std::sin(0.01 * rep);
        const auto t0 = Clock::now();
        nonlinear += fast.evaluate(contacts.data(), static_cast<int>(contacts.size()), sol) == MultirateSource::kNonlinear;
        tm.push_back(us_since(t0));
      }
      std::printf("%zu contact nodes, solve only: linear p50 %.2f p99 %.2f us; corotational p50 %.2f p99 %.2f us; "
                  "multirate (local model) p50 %.2f p99 %.2f us (%d of %d ticks on the snapshot)\n",
                  ten.size(), bench::percentile(tl, 0.5), bench::percentile(tl, 0.99), bench::percentile(co.tick_us, 0.5),
                  bench::percentile(co.tick_us, 0.99), bench::percentile(tm, 0.5), bench::percentile(tm, 0.99), nonlinear,
                  10 * repeats);
    }
    {
      const SurfaceMesh surface = boundary_surface(o.mesh);
      std::vector<int> ten(punch.begin(), punch.begin() + std::min<std::size_t>(10, punch.size()));
      std::vector<Contact> contacts;
      for (int k : ten) contacts.push_back({k, Eigen::Vector3d(0, 0, -0.008)});
      ContactSolution sol;
      haptic.solve(contacts.data(), static_cast<int>(contacts.size()), sol);
      std::printf("\nVisual frame (SurfaceDeformer::apply, %d visible nodes, %d contacts; us)\n",
                  static_cast<int>(o.visible.size()), sol.count);
      std::printf("%-14s | %8s %8s %8s\n", "deformation", "p50", "p99", "max");
      for (LiverDeformation d : {LiverDeformation::kLinear, LiverDeformation::kCorotational}) {
        SurfaceDeformer def(o.mesh, surface, &tensors, nullptr, d);
        std::vector<double> t;
        for (int rep = 0; rep < repeats; ++rep) {
          Eigen::Vector3d lambda[kMaxContacts];
          for (int l = 0; l < sol.count; ++l) lambda[l] = sol.lambda[static_cast<std::size_t>(l)] * (1 + 0.01 * std::sin(0.1 * rep));
          const auto t0 = Clock::now();
          def.apply(sol.nodes.data(), lambda, sol.count);
          t.push_back(us_since(t0));
        }
        std::printf("%-14s | %8.1f %8.1f %8.1f\n", to_string(d), bench::percentile(t, 0.5), bench::percentile(t, 0.99),
                    *std::max_element(t.begin(), t.end()));
      }
    }
    std::printf("\nTotal %.1f s\n", us_since(start) * 1e-6);
    if (!out_dir.empty()) progress("CSV in " + out_dir + "/liver_large_deformation.csv");
  } catch (const std::exception& e) {
    std::cerr << "large_deformation_bench: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
