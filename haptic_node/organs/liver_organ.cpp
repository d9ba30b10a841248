#include "organs/liver_organ.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <nlohmann/json.hpp>
#include <ostream>
#include <string>
#include <utility>
#include <vector>

#include "core/error.h"
#include "haptic_dds.h"
#include "liver/liver_setup.h"
#include "nonlinear/organ_curves.h"
#include "mesher/scene_mesh.h"

using namespace surgsim::core;
using namespace surgsim::mesh;
using namespace surgsim::fem;
using namespace surgsim::compliance;
using namespace surgsim::nonlinear;
using namespace surgsim::contact;
using namespace surgsim::liver;
using namespace surgsim::intestine;
using namespace surgsim::scene;
using namespace surgsim::mesher;

namespace surgsim {

namespace {

// The liver's surface triangles over all its nodes (the triangles index the tetrahedral mesh's nodes).
TriSurface surface_of(const LiverModel& model, const std::string& where) {
  TriSurface t;
  t.vertices = model.mesh.nodes;
  t.tris = model.surface.tris;
  t.source = where;
  return t;
}

}  // namespace

LiverObstacle::LiverObstacle(const LiverOrgan& liver, const std::string& where)
    : liver_(liver), rest_(surface_of(liver.model(), where), false, where), generation_(liver.model().generation) {}

bool LiverObstacle::nearest(const Eigen::Vector3d& p, double max_distance, intestine::ObstacleHit& hit) const noexcept {
  if (liver_.model().generation != generation_) return false;  // cut: the rest surface is not the liver's any more
  const rigid::ClosestPoint c = rest_.closest_point(p, max_distance + kDentReach);
  if (!c.found) return false;
  // The same barycentric point of the deformed triangle (the rest surface's vertices are the mesh's nodes).
  const ToolContacts& contacts = liver_.liver_contacts();
  const Eigen::Vector3d da = contacts.deformed(c.corners[0]), db = contacts.deformed(c.corners[1]),
                        dd = contacts.deformed(c.corners[2]);
  const Eigen::Vector3d q = c.bary[0] * da + c.bary[1] * db + c.bary[2] * dd;
  Eigen::Vector3d n = (db - da).cross(dd - da);
  const double len = n.norm();
  if (!(len > 0) || !q.allFinite()) return false;
  n /= len;
  const double distance = (p - q).dot(n);
  if (!std::isfinite(distance) || distance > max_distance) return false;
  hit.distance = distance;
  hit.normal = n;
  return true;
}

bool LiverObstacle::nearest(int node, const Eigen::Vector3d& p, double max_distance,
                            intestine::ObstacleHit& hit) const noexcept {
  if (liver_.model().generation != generation_) return false;
  const int j = coupled() && node >= 0 && node < static_cast<int>(point_of_node_.size())
                    ? point_of_node_[static_cast<std::size_t>(node)]
                    : -1;
  if (j == kAway) return false;  // gather() found it clear of the liver's current surface
  const ToolContacts& contacts = liver_.liver_contacts();
  if (j < 0 || j >= contacts.body_count() || !contacts.body_force(j).solved) return nearest(p, max_distance, hit);
  // The liver's solve took this node: its push, as the overlap the bowel's penalty turns back into that push.
  const double push = contacts.body_force(j).push;
  if (!(push > 0)) return false;  // the solve let go: not touching
  hit.distance = max_distance - push / body_stiffness_;
  hit.normal = contacts.body(j).normal;
  return true;
}

void LiverObstacle::couple(const IntestineModel& model, const IntestineState& state, const std::string& where) {
  if (coupled()) throw_error(where, ": a second body resting on the same liver (one is solved with it)");
  body_model_ = &model;
  body_state_ = &state;
  body_stiffness_ = model.params().obstacle_stiffness;
  point_of_node_.assign(static_cast<std::size_t>(model.node_count()), -1);
}

int LiverObstacle::gather(const ToolContacts& contacts, BodyPoint* out, int room) noexcept {
  if (!coupled()) return 0;
  std::fill(point_of_node_.begin(), point_of_node_.end(), -1);
  if (liver_.model().generation != generation_ || !(body_stiffness_ > 0)) return 0;
  const Eigen::Matrix3Xd& x = body_state_->x;
  const int nodes = std::min(static_cast<int>(x.cols()), static_cast<int>(point_of_node_.size()));
  const double reach = kDentReach + kEngage;
  int n = 0;
  const Eigen::AlignedBox3d& box = rest_.bounds();
  for (int node = 0; node < nodes; ++node) {
    const double radius = obstacle_radius(*body_model_, node);
    if (!(radius > 0)) continue;
    const Eigen::Vector3d p = x.col(node);
    if (!(box.exteriorDistance(p) <= radius + reach)) {  // far from the liver (or not finite: the step refuses it)
      if (p.allFinite()) point_of_node_[static_cast<std::size_t>(node)] = kAway;
      continue;
    }
    const rigid::ClosestPoint c = rest_.closest_point(p, radius + reach);
    if (!c.found) {
      point_of_node_[static_cast<std::size_t>(node)] = kAway;
      continue;
    }
    const double gap = c.distance - radius;  // from the rest surface
    // What the current solution already moved the surface there (the dent the instruments and the body made).
    double moved = 0;
    Eigen::Vector3d u;
    for (int k = 0; k < 3; ++k)
      if (contacts.solution_displacement(c.corners[k], u)) moved += c.bary[k] * c.normal.dot(u);
    if (!(gap - moved < kEngage)) {
      point_of_node_[static_cast<std::size_t>(node)] = kAway;
      continue;
    }
    if (n == room) {
      ++overflow_;
      continue;
    }
    BodyPoint& b = out[n];
    b.nodes = {c.corners[0], c.corners[1], c.corners[2]};
    b.bary = c.bary;
    b.normal = c.normal;
    b.gap = gap;
    b.stiffness = body_stiffness_;
    point_of_node_[static_cast<std::size_t>(node)] = n++;
  }
  return n;
}

void LiverOrgan::add_wall(const rigid::RigidSurface& surface, double stiffness, const std::string& name) {
  Wall w;
  w.surface = &surface;
  w.stiffness = stiffness;
  w.name = name;
  w.nearest_at_rest = std::numeric_limits<double>::infinity();
  std::vector<std::pair<double, int>> near;  // rest distance, node
  for (int node : this->surface().nodes) {
    if (model().fixed.node_touched(node)) continue;  // held: it does not move into anything
    const Eigen::Vector3d x = mesh().nodes.row(node).transpose();
    const rigid::ClosestPoint c = surface.closest_point(x, wall_reach_);
    if (c.found) near.emplace_back(c.distance, node);
  }
  std::sort(near.begin(), near.end());
  if (!near.empty()) w.nearest_at_rest = near.front().first;
  // The displacement bound's compliance: each loadable node's largest block G(n, c) (Frobenius) towards the new
  // nodes n, read straight from the tensors' block (only contactable nodes c take a load).
  const compliance::Superposition& g = contacts_->superposition();
  const compliance::Tensors& tensors = g.tensors();
  const compliance::TensorBlock& block = g.block();
  wall_compliance_.resize(static_cast<std::size_t>(mesh().nodes.rows()), 0.0);
  for (const auto& [distance, node] : near) {
    w.nodes.push_back(node);
    w.reach.push_back(std::max(distance - kWallEngage, 0.0));
    const int r = block.row_of_node[static_cast<std::size_t>(node)];
    if (r < 0) continue;  // not a row of the block: no load moves it
    for (std::size_t col = 0; col < tensors.contact_nodes.size(); ++col) {
      double& m = wall_compliance_[static_cast<std::size_t>(tensors.contact_nodes[col])];
      m = std::max(m, block.block3(r, static_cast<int>(col)).norm());
    }
  }
  walls_.push_back(std::move(w));
}

int LiverOrgan::gather_walls(int begin) noexcept {
  int n = begin;
  // No wall node is displaced more than `bound` (each |u_n| <= sum_c |G(n, c)| |lambda_c|).
  const compliance::ContactSolution& s = contacts_->solution();
  double bound = 0;
  for (int l = 0; l < s.count; ++l) {
    const int c = s.nodes[static_cast<std::size_t>(l)];
    if (c < 0 || c >= static_cast<int>(wall_compliance_.size())) continue;
    bound += wall_compliance_[static_cast<std::size_t>(c)] * s.lambda[static_cast<std::size_t>(l)].norm();
  }
  if (!std::isfinite(bound)) bound = std::numeric_limits<double>::infinity();
  for (Wall& w : walls_) {
    w.first = n;
    w.count = 0;
    if (!(w.stiffness > 0)) continue;
    for (std::size_t i = 0; i < w.nodes.size() && w.reach[i] <= bound; ++i) {  // nearest first
      const int node = w.nodes[i];
      Eigen::Vector3d u;
      if (!contacts_->solution_displacement(node, u)) continue;  // a fixed node, or no column: it does not move
      if (u.squaredNorm() < w.reach[i] * w.reach[i]) continue;   // not moved far enough to be near the wall
      const Eigen::Vector3d rest = mesh().nodes.row(node).transpose();
      const rigid::ClosestPoint c = w.surface->closest_point(rest + u, kWallCatch);
      if (!c.found || !(c.distance < kWallEngage)) continue;
      if (n == ToolContacts::kMaxBodyPoints) {
        ++w.dropped;
        continue;
      }
      BodyPoint& b = bodies_[static_cast<std::size_t>(n++)];
      b.nodes = {node, -1, -1};
      b.bary = Eigen::Vector3d(1, 0, 0);
      b.normal = -c.normal;                  // the row's direction: the wall pushes the node along +normal
      b.gap = c.normal.dot(rest - c.point);  // the rest position's distance from the wall along its normal
      b.stiffness = w.stiffness;
      ++w.count;
    }
  }
  return n;
}

void LiverOrgan::account_walls() noexcept {
  for (Wall& w : walls_) {
    int touching = 0;
    for (int j = w.first; j < w.first + w.count && j < contacts_->body_count(); ++j) {
      const BodyForce& f = contacts_->body_force(j);
      if (!(f.push > 0)) continue;
      ++touching;
      w.max_penetration = std::max(w.max_penetration, f.push / w.stiffness);
    }
    if (touching > 0) ++w.contact_ticks;
    w.contacts_max = std::max(w.contacts_max, touching);
  }
}

LiverObstacle& LiverOrgan::obstacle(const std::string& where) {
  if (!obstacle_) obstacle_ = std::make_unique<LiverObstacle>(*this, where);
  return *obstacle_;
}

LiverOrgan::LiverOrgan(const Scene& scene, const std::string& cache_dir, std::ostream* progress, bool tracker_thread,
                       int tracker_threads, bool rotations_in_loop) {
  TetMesh mesh = load_scene_mesh(scene, cache_dir, progress);
  const bool multirate = scene.liver.deformation == LiverDeformation::kMultirate;
  if (multirate) {
    const std::size_t surface_nodes = boundary_surface(mesh).nodes.size();
    if (surface_nodes > static_cast<std::size_t>(msg::kMaxBodyPoints)) {
      throw_error(scene.file, ": liver.deformation multirate: the liver's surface has ", surface_nodes,
                  " nodes, a BodyState carries at most ", msg::kMaxBodyPoints,
                  ": use a coarser mesh (mesh.target_nodes) or liver.deformation linear");
    }
  }
  tools_ = scene.tools;
  deformation_ = scene.liver.deformation;
  wall_reach_ = scene.liver.wall_reach;
  const LiverModelSource source{scene.material, scene.fixed, scene.nonlinear, scene.liver.organ_curves, scene.file};
  instance_ = std::make_unique<LiverInstance>(build_liver_model(std::move(mesh), source, cache_dir, progress), tools_,
                                              deformation_);
  contacts_ = &instance_->contacts();
  const LiverModel& model = instance_->model();
  if (multirate) {
    // The neo-Hookean organ on the tensors' own mesh, material and fixed set; its tracker thread is started from
    // this (the main) thread, so with --cpu N it inherits the CPUs the haptic app left to everything but the loop.
    multirate_ =
        std::make_unique<MultirateContacts>(model.mesh, scene.material, model.fixed, model.surface.nodes, scene.file);
    contacts_->attach_multirate(multirate_.get());
    instruments_at_.resize(kInstrumentTicks);
    min_period_ns_ = scene.visual.rate_hz > 0 ? static_cast<std::uint64_t>(1e9 / scene.visual.rate_hz) : 0;
    multirate_->set_numeric_threads(tracker_threads);
    if (tracker_thread) multirate_->start();
  }
  rotations_in_loop_ = rotations_in_loop && scene.liver.deformation == LiverDeformation::kCorotational;
  if (scene.liver.deformation == LiverDeformation::kCorotational && !rotations_in_loop_) {
    // Off the loop thread: the rotations of every surface node at kRotationRefreshHz (the loop keeps its contact
    // nodes' own every tick); absolute deadlines, a late refresh is skipped, not caught up.
    rotation_thread_ = std::thread([this] {
      using Clock = std::chrono::steady_clock;
      const auto period = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1 / kRotationRefreshHz));
      auto next = Clock::now();
      while (!stop_rotations_.load(std::memory_order_relaxed)) {
        contacts_->refresh_rotations();
        next += period;
        const auto now = Clock::now();
        if (next < now) next = now;
        std::this_thread::sleep_until(next);
      }
    });
  }
}

LiverOrgan::~LiverOrgan() {
  stop_rotations_.store(true);
  if (rotation_thread_.joinable()) rotation_thread_.join();
  if (multirate_ != nullptr) multirate_->stop();
}

void LiverOrgan::post_model(std::shared_ptr<const LiverModel> next) {
  if (deformation_ != LiverDeformation::kLinear) {
    throw_error("liver: a model swap between ticks needs liver.deformation linear (this liver is ",
                to_string(deformation_), ": its rotation or tracker thread is bound to the current model)");
  }
  if (next == nullptr) throw_error("liver: a model swap needs a model (got none)");
  collect_retired();
  if (incoming_.full()) throw_error("liver: the previous model swap has not been taken by the loop yet");
  auto instance = std::make_unique<LiverInstance>(std::move(next), tools_, deformation_);
  instance->contacts().time_stages(time_stages_);
  incoming_.post(instance);
}

bool LiverOrgan::collect_retired() { return retired_.take() != nullptr; }

void LiverOrgan::create_writers(dds::Participant& participant, std::uint64_t scene_hash) {
  if (multirate_ == nullptr) return;
  writer_ = participant.writer(participant.topic(dds::kBodyStateTopic, new msg::BodyStatePubSubType()),
                               dds::kStreamWriter);
  sample_.organ(static_cast<std::uint32_t>(organ_index_));  // the key: this organ's instance
  sample_.scene_hash(scene_hash);
  // The only allocations of the sample: write() changes values only.
  sample_.positions().resize(surface().nodes.size());
  sample_.instruments().resize(static_cast<std::size_t>(contacts_->instruments()));
}

void LiverOrgan::write(const TickRecord& r, std::uint64_t stamp_ns) noexcept {
  if (writer_ == nullptr || multirate_ == nullptr) return;
  // The instruments of every tick, for the BodyState of the surface computed for that tick's targets.
  InstrumentsAt& at = instruments_at_[static_cast<std::size_t>(r.seq % kInstrumentTicks)];
  at.seq = r.seq;
  at.count = r.instrument_count;
  at.instruments = r.instruments;
  if (multirate_->take_surface()) body_pending_ = true;
  if (!body_pending_ || (last_body_ns_ != 0 && stamp_ns - last_body_ns_ < min_period_ns_)) return;
  body_pending_ = false;
  const TrackerSurface& s = multirate_->surface();
  if (!s.valid) return;
  const InstrumentsAt& then = instruments_at_[static_cast<std::size_t>(s.tick % kInstrumentTicks)];
  scratch_.instrument_count = then.seq == s.tick ? then.count : r.instrument_count;
  scratch_.instruments = then.seq == s.tick ? then.instruments : r.instruments;
  fill_instruments(scratch_, sample_.instruments());
  auto& out = sample_.positions();
  const TetMesh& mesh = this->mesh();
  const SurfaceMesh& surface = this->surface();
  const std::size_t n = std::min(out.size(), surface.nodes.size());
  for (std::size_t k = 0; k < n; ++k) {
    const Eigen::Index node = surface.nodes[k];
    const Eigen::Index i = 3 * static_cast<Eigen::Index>(k);
    out[k].x(mesh.nodes(node, 0) + s.u[i]);
    out[k].y(mesh.nodes(node, 1) + s.u[i + 1]);
    out[k].z(mesh.nodes(node, 2) + s.u[i + 2]);
  }
  sample_.seq(++body_seq_);
  sample_.sim_time(s.sim_time);
  sample_.stamp_ns(stamp_ns);
  writer_->write(&sample_);
  last_body_ns_ = stamp_ns;
  body_published_.fetch_add(1, std::memory_order_relaxed);
}

void LiverOrgan::add_stats(nlohmann::json& j) const {
  if (!walls_.empty()) {
    nlohmann::json walls = nlohmann::json::array();
    for (const Wall& w : walls_) {
      walls.push_back(
          {{"organ", w.name},
           {"nodes_near", w.nodes.size()},
           {"reach_mm", 1e3 * wall_reach_},
           {"nearest_at_rest_mm", w.nodes.empty() ? nlohmann::json() : nlohmann::json(1e3 * w.nearest_at_rest)},
           {"rows_dropped", w.dropped},
           {"contact_ticks", w.contact_ticks},
           {"contacts_max", w.contacts_max},
           {"max_penetration_mm", 1e3 * w.max_penetration}});
    }
    j["walls"] = std::move(walls);
  }
  if (obstacle_ != nullptr && obstacle_->coupled()) {
    // The bowel's points left one-way: no room in the liver's solve (gathered past its points, or past its nodes).
    j["body_points_one_way"] = obstacle_->overflow() + contacts_->body_overflow();
  }
  if (multirate_ == nullptr) return;
  MultirateContacts& m = *multirate_;
  m.stop();  // shutdown: its counters and cycle times are final
  j["multirate"] = {{"tracker_cycles", m.tracker_cycles()},
                    {"snapshots_published", m.snapshots_published()},
                    {"tracker_failures", m.tracker_failures()},
                    {"idle_sleeps", m.idle_sleeps()},
                    {"cycle_ms_p50", m.cycle_ms(0.5)},
                    {"cycle_ms_p99", m.cycle_ms(0.99)},
                    {"ticks_nonlinear", m.ticks_nonlinear()},
                    {"ticks_partial", m.ticks_partial()},
                    {"ticks_linear_fallback", m.ticks_linear_fallback()},
                    {"ticks_blended", m.ticks_blended()},
                    {"snapshot_age_ms_p50", m.age_ms(0.5)},
                    {"snapshot_age_ms_p99", m.age_ms(0.99)},
                    {"snapshot_stale_ms_p50", m.stale_ms(0.5)},
                    {"snapshot_stale_ms_p99", m.stale_ms(0.99)},
                    {"extrapolation_mm_p99", m.extrapolation_mm(0.99)},
                    {"body_states_published", body_published_.load(std::memory_order_relaxed)}};
}

void LiverOrgan::print_summary(std::ostream& out) const {
  if (multirate_ == nullptr) return;
  nlohmann::json j;
  add_stats(j);
  const nlohmann::json& m = j["multirate"];
  out << "haptic_node: multirate tracker " << m["tracker_cycles"].get<std::uint64_t>() << " cycles (p50 "
      << m["cycle_ms_p50"].get<double>() << " ms, p99 " << m["cycle_ms_p99"].get<double>() << " ms), "
      << m["snapshots_published"].get<std::uint64_t>() << " snapshots; ticks nonlinear "
      << m["ticks_nonlinear"].get<std::uint64_t>() << ", partial " << m["ticks_partial"].get<std::uint64_t>()
      << ", linear fallback " << m["ticks_linear_fallback"].get<std::uint64_t>() << " (blended with linear "
      << m["ticks_blended"].get<std::uint64_t>() << "); snapshot age p99 "
      << m["snapshot_age_ms_p99"].get<double>() << " ms (stale p99 " << m["snapshot_stale_ms_p99"].get<double>()
      << " ms); " << m["body_states_published"].get<std::uint64_t>()
      << " body states published\n";
}

void LiverOrgan::step(const InstrumentInput* inputs, int count, double dt, ContactTick* out) noexcept {
  // A model swap, at the tick boundary: the new instance in, the old one out to be freed off the loop (only when the
  // previous one was collected, so the hand-off never fails and nothing is freed here).
  if (incoming_.full() && !retired_.full()) {
    std::unique_ptr<LiverInstance> next = incoming_.take();
    retired_.post(instance_);
    instance_ = std::move(next);
    contacts_ = &instance_->contacts();
  }
  // The field's bowel resting on the liver and its walls: their points solved with the instruments' (two-way).
  if (obstacle_ != nullptr || !walls_.empty()) {
    int n = obstacle_ != nullptr ? obstacle_->gather(*contacts_, bodies_.data(), ToolContacts::kMaxBodyPoints) : 0;
    n = gather_walls(n);
    contacts_->set_bodies(bodies_.data(), n);
  }
  // An instrument whose input is lost drops its own contacts and gets zero force; the others are solved as usual.
  contacts_->step(inputs, count, out, dt);
  if (!walls_.empty()) account_walls();
  // Unpaced: the background rotations refreshed here on simulated time, so a replay gives the same forces every time
  // (on the thread they depend on how many ticks ran between two wall-clock refreshes).
  if (rotations_in_loop_) {
    rotation_clock_ += dt;
    if (rotation_clock_ >= 1 / kRotationRefreshHz) {
      rotation_clock_ -= 1 / kRotationRefreshHz;
      contacts_->refresh_rotations();
    }
  }
}

ContactEntry LiverOrgan::contact_entry(int l) const noexcept {
  const ContactSolution& s = contacts_->solution();
  ContactEntry e;
  e.node = s.nodes[static_cast<std::size_t>(l)];
  e.instrument = contacts_->node_instrument(l);
  e.lambda = s.lambda[static_cast<std::size_t>(l)];
  // Multirate: the node's imposed displacement this tick (the tracker's target), which the visual node needs to carry
  // the tracker's last shape to where the tool is now; otherwise the paper's corrected constraint.
  e.u_tilde = multirate_ != nullptr ? s.displacement[static_cast<std::size_t>(l)] : contacts_->corrected(l);
  return e;
}

std::string LiverOrgan::describe() const {
  return std::to_string(mesh().nodes.rows()) + " nodes, " + std::to_string(mesh().tets.rows()) + " tets, " +
         std::to_string(surface().nodes.size()) + " surface nodes; " + to_string(contacts_->deformation()) + "; ";
}

}  // namespace surgsim
