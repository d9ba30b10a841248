// Several organs in the haptic node (organs/composite_organ.h, organs/rigid_organ.h, the factory): an instrument
// touching two organs in one tick gets the sum of what each gives it alone, bit for bit; the sum is left unclamped
// and the force stage clamps it once (clamping each organ's force first turns the sum); the organs' rest overlap and
// the second published body are refused naming the scene file, line and key; the loop allocates nothing.
#include "organs/composite_organ.h"

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "core/error.h"
#include "force_stage.h"
#include "organs/intestine_organ.h"
#include "organs/liver_organ.h"
#include "organs/rigid_organ.h"
#include "support/alloc_counter.h"
#include "support/error_test_util.h"
#include "support/intestine_test_util.h"
#include "tool/trajectory.h"

using namespace surgsim::contact;
using namespace surgsim::scene;
using namespace surgsim::tool;

namespace surgsim {
namespace {

namespace fs = std::filesystem;

fs::path test_dir() {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  const fs::path dir = fs::path(::testing::TempDir()) / (std::string("composite_organ_test_") + info->name());
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

std::string write(const fs::path& path, const std::string& text) {
  std::ofstream(path, std::ios::binary) << text;
  return path.string();
}

// The plate (0.2 x 0.2 x 0.01 m, top at z = 0.005, corners fixed) and a vertical wall standing on it at x = 0.09,
// facing -x, its bottom edge 0.5 mm above the plate's top; a 10 mm instrument pressing down at x = 0.087, whose tip
// sphere (its leading point the tip) overlaps the wall by 2 mm; the tip ends 4 mm into the plate (the sphere's centre
// 5 mm above it, above the wall's bottom edge).
const std::string kTool =
    "tools:\n"
    "  - {name: probe, trocar: [0.087, 0.0, 0.15], axis: [0, 0, -1], shaft_points: 1, tip_radius: 0.005, "
    "force_limit: 8}\n";
const std::string kPlate =
    "  - name: plate\n"
    "    model: liver\n"
    "    mesh: {generate: plate, target_nodes: 300}\n"
    "    fixed:\n"
    "      boxes:\n"
    "        - {min: [-0.101, -0.101, -0.006], max: [-0.080, -0.080, 0.006]}\n"
    "        - {min: [ 0.080, -0.101, -0.006], max: [ 0.101, -0.080, 0.006]}\n"
    "        - {min: [-0.101,  0.080, -0.006], max: [-0.080,  0.101, 0.006]}\n"
    "        - {min: [ 0.080,  0.080, -0.006], max: [ 0.101,  0.101, 0.006]}\n";
const std::string kWall =
    "  - name: wall\n"
    "    model: rigid\n"
    "    rigid: {generate: plane, size: [0.1, 0.2, 0]}\n"
    "    placement: {translation: [0.09, 0, 0.0555], rotation_deg: [0, -90, 0]}\n";

Scene scene_of(const fs::path& dir, const char* file, const std::string& organs) {
  return load_scene(write(dir / file, "name: t\n" + kTool + "organs:\n" + organs));
}

// The instrument's tip straight down at 0.05 m/s from 1 cm above the plate to 4 mm into it, at 1 kHz.
std::vector<ToolGeometry> press(const ToolSpec& spec) {
  std::vector<ToolGeometry> path;
  Pose5 p;
  for (int k = 0; k <= 280; ++k) {
    p.insertion = 0.15 - 0.005 - 0.01 + 5e-5 * k;  // the tip 1 cm above the top at k = 0
    path.push_back(tool_geometry(spec, p));
  }
  return path;
}

std::vector<ContactTick> run(HapticOrgan& organ, const std::vector<ToolGeometry>& path) {
  std::vector<ContactTick> out;
  for (const ToolGeometry& g : path) {
    ContactTick t;
    organ.step(&g, 0.0, 1e-3, t);
    out.push_back(t);
  }
  return out;
}

TEST(CompositeOrgan, TwoOrgansInOneTickGiveTheSumOfEachAloneBitForBit) {
  const fs::path dir = test_dir();
  const Scene both = scene_of(dir, "both.yaml", kPlate + kWall);
  const Scene plate = scene_of(dir, "plate.yaml", kPlate);
  const Scene wall = scene_of(dir, "wall.yaml", kWall);
  const auto organ = make_haptic_organ(both, SURGSIM_TEST_CACHE_DIR, 10, nullptr);
  const auto plate_alone = make_haptic_organ(plate, SURGSIM_TEST_CACHE_DIR, 10, nullptr);
  const auto wall_alone = make_haptic_organ(wall, SURGSIM_TEST_CACHE_DIR, 10, nullptr);
  ASSERT_STREQ(organ->model_name(), "organs");
  const auto path = press(both.tools[0]);
  const auto sum = run(*organ, path);
  const auto a = run(*plate_alone, path);
  const auto b = run(*wall_alone, path);
  int both_in_contact = 0;
  double largest = 0;
  for (std::size_t k = 0; k < path.size(); ++k) {
    const Eigen::Vector3d expected = a[k].force + b[k].force;
    ASSERT_EQ(sum[k].force, expected) << "tick " << k;
    ASSERT_EQ(sum[k].device_force, expected) << "tick " << k << ": the composite leaves the clamp to the force stage";
    EXPECT_EQ(sum[k].points_in_contact, a[k].points_in_contact + b[k].points_in_contact);
    if (a[k].points_in_contact > 0 && b[k].points_in_contact > 0) {
      ++both_in_contact;
      largest = std::max(largest, expected.norm());
    }
  }
  // The instrument touches both organs over the last 80 ticks: the wall pushes it back along -x (4 N), the soft plate
  // (3 kPa, 1 cm thick) up by about 15 mN at 4 mm.
  EXPECT_GT(both_in_contact, 50);
  const ContactTick& last = sum.back();
  EXPECT_LT(last.force.x(), -1.0);
  EXPECT_GT(last.force.z(), 0.005);
  std::cout << "[composite] " << both_in_contact << " ticks on both organs; last force (" << last.force.transpose()
            << ") N = plate (" << a.back().force.transpose() << ") + wall (" << b.back().force.transpose() << ")\n";
  // The contact entries are the plate's, tagged with its index; the wall deforms nothing.
  EXPECT_EQ(organ->contact_entries(), plate_alone->contact_entries());
  for (int l = 0; l < organ->contact_entries(); ++l) EXPECT_EQ(organ->contact_entry(l).organ, 0);
  // Per-organ identities, in the scene's order.
  const auto ids = organ->identities();
  ASSERT_EQ(ids.size(), 2u);
  EXPECT_EQ(ids[0].name, "plate");
  EXPECT_EQ(ids[0].model, "liver");
  EXPECT_EQ(ids[0].mesh_hash, plate_alone->identities()[0].mesh_hash);
  EXPECT_EQ(ids[1].name, "wall");
  EXPECT_EQ(ids[1].model, "rigid");
}

// A corner of two walls: the tip 5 mm into one (10 N) and 1 mm into the other (2 N) with an 8 N device. Clamping each
// organ's force to 8 N and then the sum points the force at (8, 2); the sum clamped once points it at (10, 2).
TEST(CompositeOrgan, TheSumIsClampedOnceInTheForceStage) {
  const fs::path dir = test_dir();
  const std::string walls =
      "  - name: side\n"
      "    model: rigid\n"
      "    rigid: {generate: plane, size: [0.1, 0.1, 0], stiffness: 2000, damping: 0}\n"
      "    placement: {translation: [0, 0, 0.05], rotation_deg: [0, 90, 0]}\n"  // x = 0, z in [0, 0.1], normal +x
      "  - name: floor\n"
      "    model: rigid\n"
      "    rigid: {generate: plane, size: [0.1, 0.1, 0], stiffness: 2000, damping: 0}\n"
      "    placement: {translation: [0.05, 0, 0]}\n";  // z = 0, x in [0, 0.1], normal +z: they meet along an edge
  const Scene s = load_scene(write(dir / "corner.yaml",
                                   "name: corner\ntools:\n  - {name: probe, trocar: [0.02, 0.0, 0.2], axis: [0, 0, -1], "
                                   "shaft_points: 1, tip_radius: 0.005, force_limit: 8}\norgans:\n" +
                                       walls));
  const auto organ = make_haptic_organ(s, SURGSIM_TEST_CACHE_DIR, 10, nullptr);
  // The tip sphere's centre at x = 0 (5 mm into the side wall's offset surface at x = 0.005) and z = 0.004 (1 mm into
  // the floor's at z = 0.005): the tip, its leading point, 5 mm below along the shaft (straight down).
  ToolGeometry g = tool_geometry(s.tools[0], Pose5{});
  g.tip = Eigen::Vector3d(0.0, 0.0, -0.001);
  ContactTick t;
  organ->step(&g, 0.0, 1e-3, t);
  const auto& c = dynamic_cast<const CompositeOrgan&>(*organ);
  const Eigen::Vector3d side = c.organ_tick(0, 0).force, floor = c.organ_tick(1, 0).force;
  EXPECT_NEAR(side.x(), 10.0, 1e-5);  // the proxy stands a skin of 1-2 nm off the surface
  EXPECT_NEAR(floor.z(), 2.0, 1e-5);
  ASSERT_EQ(t.device_force, side + floor);
  EXPECT_FALSE(t.saturated);  // not yet: the composite does not clamp
  ForceStage stage(HapticSpec{}, 8.0);
  stage.apply(g, 1e-3, t);
  EXPECT_TRUE(t.saturated);
  EXPECT_NEAR(t.device_force.norm(), 8.0, 1e-9);
  const Eigen::Vector3d once = (side + floor).normalized();
  const Eigen::Vector3d twice = (Eigen::Vector3d(8, 0, 0) + floor).normalized();
  EXPECT_NEAR(t.device_force.normalized().dot(once), 1.0, 1e-12);
  EXPECT_LT(t.device_force.normalized().dot(twice), 1.0 - 1e-4) << "clamped per organ first";
}

TEST(CompositeOrgan, StepAllocatesNothing) {
  const fs::path dir = test_dir();
  const Scene both = scene_of(dir, "both.yaml", kPlate + kWall);
  const auto organ = make_haptic_organ(both, SURGSIM_TEST_CACHE_DIR, 10, nullptr);
  const auto path = press(both.tools[0]);
  OrganOutputs out;
  std::vector<double> points(3 * static_cast<std::size_t>(std::max(organ->output_points(), 1)));
  out.points = points.data();
  out.point_capacity = organ->output_points();
  ContactTick t;
  organ->step(&path[0], 0.0, 1e-3, t);  // first tick: proxies reset, contacts found
  long allocations = 0;
  {
    test::AllocationCounter counter;
    for (const ToolGeometry& g : path) {
      organ->step(&g, 0.0, 1e-3, t);
      organ->fill_outputs(out);
    }
    organ->step(nullptr, 0.0, 1e-3, t);  // input lost
    allocations = counter.count();
  }
  EXPECT_EQ(allocations, 0);
}

TEST(CompositeOrgan, OrgansOverlappingAtRestAreRefusedNamingBoth) {
  const fs::path dir = test_dir();
  // The wall down through the plate: the plate's edge 1 cm behind it.
  std::string wall = kWall;
  wall.replace(wall.find("0.0555"), 6, "0.0300");
  const Scene s = scene_of(dir, "overlap.yaml", kPlate + wall);
  const std::string e = test::error_of([&] { make_haptic_organ(s, SURGSIM_TEST_CACHE_DIR, 10, nullptr); });
  EXPECT_NE(e.find("overlap.yaml:"), std::string::npos) << e;
  EXPECT_NE(e.find("organ 'plate'"), std::string::npos) << e;
  EXPECT_NE(e.find("organ 'wall'"), std::string::npos) << e;
  EXPECT_NE(e.find("key 'organs["), std::string::npos) << e;
  EXPECT_NE(e.find("mm inside"), std::string::npos) << e;
}

TEST(CompositeOrgan, RigidOrganHoldsTheTipOnTheWallAndResetsAfterALostInput) {
  const fs::path dir = test_dir();
  const Scene s = scene_of(dir, "wall.yaml", kWall);
  const auto organ = make_haptic_organ(s, SURGSIM_TEST_CACHE_DIR, 10, nullptr);
  const auto& rigid = dynamic_cast<const RigidOrgan&>(dynamic_cast<const CompositeOrgan&>(*organ).organ(0));
  ToolGeometry g = tool_geometry(s.tools[0], Pose5{});
  ContactTick t;
  for (int k = 0; k <= 20; ++k) {  // into the wall (offset surface at x = 0.085) up to 1 mm
    g.tip = Eigen::Vector3d(0.085 - 0.001 + 1e-4 * k, 0, 0.05);
    organ->step(&g, 0.0, 1e-3, t);
  }
  EXPECT_NEAR(rigid.proxy(0).proxy_point().x(), 0.085, 1e-8);
  EXPECT_NEAR(rigid.max_penetration(0), 0.001, 1e-8);
  EXPECT_LT(t.force.x(), -1.9);  // 2000 N/m x 1 mm, plus the damper while moving in
  organ->step(nullptr, 0.0, 1e-3, t);
  EXPECT_TRUE(t.force.isZero(0));
  EXPECT_EQ(organ->contacts(), 0);
  g.tip.x() = 0.086;  // back 1 mm in: the proxy starts again on the free side
  organ->step(&g, 0.0, 1e-3, t);
  EXPECT_NEAR(rigid.proxy(0).proxy_point().x(), 0.085, 1e-8);
  EXPECT_NEAR(t.force.x(), -2.0, 1e-4);  // no damper kick: a reset is not an impact
}

// Organs that touch: the bowel of the shipped field (its vessel along x through the origin, its lowest sphere 59.6 mm
// below the vessel as built, 63.5 mm once it hangs under its weight) above a floor at z = -0.061. Through the
// composite the bowel rests on the floor; the same bowel alone sags through where the floor would be.
const std::string kBowel =
    "  - name: bowel\n"
    "    model: intestine\n"
    "    intestine: {length: 1.2, cylinder_radius: 0.05, folds: 4, columns: 50, rows: 4, intestine_radius: 0.012,\n"
    "                mesentery_thickness: 0.008, intestine_node_mass: 0.008, mesentery_node_mass: 0.003,\n"
    "                detector: broad_phase}\n";
const std::string kFloor =
    "  - name: floor\n"
    "    model: rigid\n"
    "    rigid: {generate: plane, size: [0.6, 0.4, 0]}\n"
    "    placement: {translation: [0, 0, -0.061]}\n";

// The organ of a one-organ scene, whether make_haptic_organ built it alone or as a composite of one.
const HapticOrgan& only_organ(const HapticOrgan& organ) {
  const auto* composite = dynamic_cast<const CompositeOrgan*>(&organ);
  return composite != nullptr ? composite->organ(0) : organ;
}

// The bowel of `field` (organ `index`) and the same bowel alone (`alone`), each stepped 3 s at 1 kHz with no
// instrument: the body under its weight.
struct BowelRuns {
  std::unique_ptr<HapticOrgan> field, alone;
  const IntestineOrgan* bowel = nullptr;       // in the field
  const IntestineOrgan* free_bowel = nullptr;  // alone
};
BowelRuns rest_3s(const Scene& field, int index, const Scene& alone) {
  BowelRuns r;
  r.field = make_haptic_organ(field, SURGSIM_TEST_CACHE_DIR, 3000, nullptr);
  r.alone = make_haptic_organ(alone, SURGSIM_TEST_CACHE_DIR, 3000, nullptr);
  r.bowel = &dynamic_cast<const IntestineOrgan&>(dynamic_cast<const CompositeOrgan&>(*r.field).organ(index));
  r.free_bowel = &dynamic_cast<const IntestineOrgan&>(only_organ(*r.alone));
  const InstrumentInput none{nullptr, 0.0};
  ContactTick t;
  for (int k = 0; k < 3000; ++k) {
    r.field->step(&none, 1, 1e-3, &t);
    r.alone->step(&none, 1, 1e-3, &t);
  }
  return r;
}

double bowel_bottom(const IntestineOrgan& bowel, double half = std::numeric_limits<double>::infinity()) {
  return intestine::test::lowest_sphere(bowel.model(), bowel.state().x, half);
}

TEST(CompositeOrgan, TheBowelRestsOnTheFieldsRigidOrgans) {
  const fs::path dir = test_dir();
  const BowelRuns r = rest_3s(scene_of(dir, "field.yaml", kBowel + kFloor), 0, scene_of(dir, "alone.yaml", kBowel));
  const HapticOrgan* organ = r.field.get();
  const IntestineOrgan &bowel = *r.bowel, &free_bowel = *r.free_bowel;
  ASSERT_EQ(bowel.obstacle_count(), 1);
  ASSERT_EQ(free_bowel.obstacle_count(), 0);
  EXPECT_LT(bowel_bottom(free_bowel), -0.0625) << "the control must sag through where the floor is";
  EXPECT_GT(bowel_bottom(bowel), -0.061 - 1e-3) << "the bowel went through the floor";
  nlohmann::json stats;
  organ->add_stats(stats);
  const nlohmann::json& obstacles = stats["organs"][0]["intestine"]["obstacles"];
  ASSERT_EQ(obstacles.size(), 1u) << stats.dump(2);
  EXPECT_EQ(obstacles[0]["organ"], "floor");
  EXPECT_GT(obstacles[0]["contacts_max"].get<int>(), 0);
  EXPECT_GT(obstacles[0]["contact_ticks"].get<int>(), 1000) << "it rests there, not bounces off";
  EXPECT_LT(obstacles[0]["max_penetration_mm"].get<double>(), 1.0);
  EXPECT_EQ(stats["organs"][0]["intestine"]["faults"].get<int>(), 0);
}

// The bowel on the liver, both ways: the same bowel 2 mm above the plate's top (z = 0.005), a liver model held at its
// four corners. The bowel's spheres are rows of the plate's own solve: the plate dents under them (its contact
// solution holds their loads, which the visual node draws), the bowel rests on the dented surface (less than 1 mm into
// it), what the plate takes is what the bowel feels (action and reaction), and the plate and the mesentery's root
// carry the bowel's weight. Alone, the bowel sags through where the plate is.
TEST(CompositeOrgan, TheBowelRestsOnTheLiverWhichDentsUnderIt) {
  const fs::path dir = test_dir();
  // Without self-collisions: their response moves positions, which no force accounts for (as the obstacle test).
  std::string bowel_placed = kBowel + "    placement: {translation: [0, 0, 0.0666]}\n";
  bowel_placed.replace(bowel_placed.find("detector: broad_phase}"), 22,
                       "detector: broad_phase, self_collisions: false}");
  // The plate held on its underside (at its corners alone it is so soft that the root ends up carrying the bowel).
  const std::string plate = kPlate.substr(0, kPlate.find("    fixed:")) +
                            "    fixed: {plane: {point: [0, 0, -0.0049], normal: [0, 0, -1]}}\n";
  const BowelRuns r =
      rest_3s(scene_of(dir, "field.yaml", plate + bowel_placed), 1, scene_of(dir, "alone.yaml", bowel_placed));
  const HapticOrgan* organ = r.field.get();
  const IntestineOrgan &bowel = *r.bowel, &free_bowel = *r.free_bowel;
  double speed = 0;
  for (int n = 0; n < bowel.model().node_count(); ++n) speed = std::max(speed, bowel.state().v.col(n).norm());
  std::cout << "[bowel on plate] fastest node " << speed << " m/s after 3 s\n";
  const auto& plate_organ = dynamic_cast<const LiverOrgan&>(dynamic_cast<const CompositeOrgan&>(*organ).organ(0));
  ASSERT_EQ(bowel.obstacle_count(), 1);
  EXPECT_LT(bowel_bottom(free_bowel, 0.095), 0.005 - 1.5e-3) << "the control must sag through the plate";
  nlohmann::json stats;
  organ->add_stats(stats);
  const nlohmann::json& obstacles = stats["organs"][1]["intestine"]["obstacles"];
  ASSERT_EQ(obstacles.size(), 1u) << stats.dump(2);
  EXPECT_EQ(obstacles[0]["organ"], "plate");
  EXPECT_GT(obstacles[0]["contact_ticks"].get<int>(), 1000);
  EXPECT_LT(obstacles[0]["max_penetration_mm"].get<double>(), 1.0) << "into the dented surface";
  EXPECT_EQ(stats["organs"][1]["intestine"]["faults"].get<int>(), 0);
  // The plate's contact solution holds the bowel's loads: entries of no instrument, pushing down.
  const ToolContacts& contacts = plate_organ.liver_contacts();
  int body_entries = 0;
  double dent = 0;
  for (int l = 0; l < plate_organ.contact_entries(); ++l) {
    const ContactEntry e = plate_organ.contact_entry(l);
    if (e.instrument != ToolContacts::kBodyInstrument) continue;
    ++body_entries;
    EXPECT_LT(e.lambda.z(), 0) << "node " << e.node;
    Eigen::Vector3d u;
    ASSERT_TRUE(contacts.solution_displacement(e.node, u));
    dent = std::min(dent, u.z());
  }
  EXPECT_GT(body_entries, 3);
  EXPECT_LT(dent, -1e-4) << "the plate must dent under the bowel";
  EXPECT_EQ(contacts.body_overflow(), 0);
  // Action and reaction, and the balance, as means over one more second: the bowel never quite stops (its stochastic
  // self-collisions), and its implicit step ends each tick on the push linearized over its own motion in the tick,
  // while the plate took the push at its start; on average the motion is nothing.
  Eigen::Vector3d on_bowel = Eigen::Vector3d::Zero(), on_plate = Eigen::Vector3d::Zero(),
                  root = Eigen::Vector3d::Zero();
  const InstrumentInput none{nullptr, 0.0};
  ContactTick t;
  constexpr int kTicks = 1000;
  for (int k = 0; k < kTicks; ++k) {
    r.field->step(&none, 1, 1e-3, &t);
    on_bowel += bowel.report().obstacles[0].force / kTicks;
    on_plate += contacts.body_load() / kTicks;
    root += intestine::test::root_reaction(bowel.model(), bowel.state()) / kTicks;
  }
  EXPECT_LT((on_bowel + on_plate).norm(), 0.01 * on_bowel.norm())
      << "bowel " << on_bowel.transpose() << " N, plate " << on_plate.transpose() << " N";
  // The balance: the plate and the root carry the bowel's weight, within 1 % of it.
  const Eigen::Vector3d w = intestine::test::weight(bowel.model());
  const Eigen::Vector3d residual = on_bowel + root + w;
  std::cout << "[bowel on plate] weight " << -w.z() << " N: plate " << on_bowel.z() << " N (its load " << -on_plate.z()
            << " N), root " << root.z() << " N, residual " << residual.norm() / w.norm() << " of the weight; dent "
            << -dent * 1e3 << " mm, " << body_entries << " loaded nodes\n";
  EXPECT_GT(on_bowel.z(), 0.1 * w.norm()) << "the plate carries a real share";
  EXPECT_LT(residual.norm(), 0.01 * w.norm());
}

// The shipped field (config/abdomen.yaml) left alone for 60 s at 1 kHz: the bowel falls from its rest shape onto the
// liver's lower edge and settles there, its mesentery taking most of its weight. Never a fault or a non-finite value;
// the bowel's kinetic energy after the first 10 s (settling) never exceeds what it reached while settling and ends
// small; the liver's load from the bowel stays bounded, and after settling never leaves it: the bowel rests on the
// liver.
TEST(CompositeOrgan, TheShippedFieldRestsSixtySecondsWithBoundedEnergy) {
  const Scene s = load_scene(std::string(SURGSIM_TEST_CONFIG_DIR) + "/abdomen.yaml");
  const auto organ = make_haptic_organ(s, SURGSIM_TEST_CACHE_DIR, 10, nullptr);
  const auto& field = dynamic_cast<const CompositeOrgan&>(*organ);
  const IntestineOrgan* bowel = nullptr;
  const LiverOrgan* liver = nullptr;
  for (int k = 0; k < field.organ_count(); ++k) {
    if (bowel == nullptr) bowel = dynamic_cast<const IntestineOrgan*>(&field.organ(k));
    if (liver == nullptr) liver = dynamic_cast<const LiverOrgan*>(&field.organ(k));
  }
  ASSERT_NE(bowel, nullptr);
  ASSERT_NE(liver, nullptr);
  const auto& masses = bowel->model().mass_spring().mass();
  const auto kinetic = [&] {
    double e = 0;
    for (int n = 0; n < bowel->model().node_count(); ++n)
      e += 0.5 * masses[static_cast<std::size_t>(n)] * bowel->state().v.col(n).squaredNorm();
    return e;
  };
  const InstrumentInput none[2] = {{nullptr, 0.0}, {nullptr, 0.0}};
  ContactTick t[2];
  double settling_max = 0, rest_max = 0, end = 0, load_min = 1e300, load_max = 0;
  int nonfinite = 0, liver_ticks = 0;
  for (int k = 0; k < 60000; ++k) {
    organ->step(none, 2, 1e-3, t);
    const double e = kinetic();
    if (!std::isfinite(e) || !t[0].force.allFinite() || !t[1].force.allFinite()) ++nonfinite;
    const double load = liver->liver_contacts().body_load().norm();
    load_max = std::max(load_max, load);
    if (k < 10000) {
      settling_max = std::max(settling_max, e);
      continue;
    }
    rest_max = std::max(rest_max, e);
    if (k >= 59000) end = std::max(end, e);
    if (load > 0) ++liver_ticks;
    load_min = std::min(load_min, load);
  }
  std::cout << "[field at rest] bowel kinetic energy: settling max " << settling_max << " J, 10-60 s max " << rest_max
            << " J, last second max " << end << " J; liver's load from the bowel after 10 s " << load_min
            << " N at least, " << load_max << " N at most over the run, " << liver_ticks << " ticks with a load\n";
  EXPECT_EQ(nonfinite, 0);
  EXPECT_EQ(bowel->faults(), 0u);
  EXPECT_LE(rest_max, settling_max) << "the energy grew after settling";
  EXPECT_LT(end, 0.1 * settling_max);
  EXPECT_LT(load_max, 2.0) << "the bowel's weight is about 7 N, most of it on its root";
  EXPECT_EQ(liver_ticks, 50000) << "the bowel slid off the liver";
  EXPECT_GT(load_min, 0.0);
  EXPECT_TRUE(t[0].force.isZero(0)) << "no instrument: no force";
}

// The liver against a rigid organ: the plate (held at its corners) over a floor 2 mm below its underside, pressed 4 mm
// at its centre. Its underside's nodes are rows of its own solve against the floor: they stop on it (less than 1 mm
// into it, the floor's 2000 N/m penalty), and the instrument feels the floor through the plate. Alone, the same press
// takes the underside through where the floor is.
TEST(CompositeOrgan, TheLiverStopsOnARigidOrganUnderAnInstrumentsPress) {
  const fs::path dir = test_dir();
  const std::string floor =
      "  - name: floor\n"
      "    model: rigid\n"
      "    rigid: {generate: plane, size: [0.3, 0.3, 0]}\n"
      "    placement: {translation: [0, 0, -0.007]}\n";
  const Scene both = scene_of(dir, "on_floor.yaml", kPlate + floor);
  const Scene alone = scene_of(dir, "plate.yaml", kPlate);
  const auto organ = make_haptic_organ(both, SURGSIM_TEST_CACHE_DIR, 10, nullptr);
  const auto plate_alone = make_haptic_organ(alone, SURGSIM_TEST_CACHE_DIR, 10, nullptr);
  const auto& plate = dynamic_cast<const LiverOrgan&>(dynamic_cast<const CompositeOrgan&>(*organ).organ(0));
  ASSERT_EQ(plate.wall_count(), 1);
  const auto path = press(both.tools[0]);
  const auto with = run(*organ, path);
  const auto without = run(*plate_alone, path);
  // The lowest point of the underside under each solution.
  const auto lowest = [](const LiverOrgan& liver) {
    double z = 1;
    for (int n : liver.surface().nodes) {
      Eigen::Vector3d u;
      if (liver.liver_contacts().solution_displacement(n, u)) z = std::min(z, liver.mesh().nodes(n, 2) + u.z());
    }
    return z;
  };
  const auto& plate_only = dynamic_cast<const LiverOrgan&>(only_organ(*plate_alone));
  const double z_with = lowest(plate), z_without = lowest(plate_only);
  nlohmann::json stats;
  organ->add_stats(stats);
  const nlohmann::json& walls = stats["organs"][0]["walls"];
  std::cout << "[plate on floor] lowest underside point " << z_with * 1e3 << " mm (alone " << z_without * 1e3
            << " mm; floor at -7 mm); force " << with.back().force.z() << " N (alone " << without.back().force.z()
            << " N); " << walls.dump() << "\n";
  EXPECT_LT(z_without, -0.007 - 0.001) << "the control must go through where the floor is";
  EXPECT_GT(z_with, -0.007 - 0.001);
  ASSERT_EQ(walls.size(), 1u);
  EXPECT_EQ(walls[0]["organ"], "floor");
  EXPECT_GT(walls[0]["contact_ticks"].get<int>(), 10);
  EXPECT_LT(walls[0]["max_penetration_mm"].get<double>(), 1.0);
  EXPECT_GT(with.back().force.z(), without.back().force.z() + 0.01) << "the floor must hold the plate up";
}

// The shipped field along its second trajectory (config/trajectories/abdomen_lift.csv) at 1 kHz, as the haptic node
// replays it: the probe grasps the liver's right lobe by its anterior edge, lifts it 6 cm and carries it 2.8 cm
// cranially over the first rib, the edge drawn onto the rib, while the grasper holds a loop of bowel on the liver's
// lower edge. The liver touches the ribs (their rows push)
// and goes less than 1 mm into them or any other rigid organ, by the rows' pushes (the stats) and by every surface
// node's signed distance from every rigid surface every 10th tick; the bowel goes less than 1 mm into any rigid organ
// (its obstacles' stats). Without the wall rows (gather_walls adding none) the edge goes 4.8 mm into the rib and the
// rows' stats count no contact.
TEST(CompositeOrgan, TheLiftedLiversEdgeStopsOnTheRibsAlongTheShippedLift) {
  const std::string config = SURGSIM_TEST_CONFIG_DIR;
  const Scene s = load_scene(config + "/abdomen.yaml");
  const MultiTrajectory trajectory = MultiTrajectory::load(config + "/trajectories/abdomen_lift.csv");
  const auto organ = make_haptic_organ(s, SURGSIM_TEST_CACHE_DIR, 10, nullptr);
  const auto& field = dynamic_cast<const CompositeOrgan&>(*organ);
  const LiverOrgan* liver = nullptr;
  std::vector<std::pair<std::string, const rigid::RigidSurface*>> rigids;
  for (int k = 0; k < field.organ_count(); ++k) {
    if (liver == nullptr) liver = dynamic_cast<const LiverOrgan*>(&field.organ(k));
    if (const auto* r = dynamic_cast<const RigidOrgan*>(&field.organ(k)))
      rigids.emplace_back(s.organs[static_cast<std::size_t>(k)].name, &r->surface());
  }
  ASSERT_NE(liver, nullptr);
  ASSERT_EQ(rigids.size(), 3u);
  const int n = static_cast<int>(s.tools.size());
  ASSERT_EQ(n, 2);
  std::vector<int> column(s.tools.size());
  for (int i = 0; i < n; ++i)
    column[static_cast<std::size_t>(i)] = trajectory.find(s.tools[static_cast<std::size_t>(i)].name);
  ASSERT_GE(column[0], 0);
  ASSERT_GE(column[1], 0);
  std::vector<double> deepest(rigids.size(), 0);  // m, each rigid organ's deepest liver node
  std::array<ToolGeometry, 2> tool;
  std::array<InstrumentInput, 2> inputs;
  std::array<ContactTick, 2> out;
  const auto ticks = static_cast<int>(std::lround(trajectory.duration() * 1e3));
  for (int k = 0; k <= ticks; ++k) {
    for (std::size_t i = 0; i < 2; ++i) {
      Pose5 pose;
      ASSERT_TRUE(trajectory.at(column[i], k * 1e-3, pose));
      tool[i] = tool_geometry(s.tools[i], pose);
      inputs[i] = InstrumentInput{&tool[i], pose.jaw};
    }
    organ->step(inputs.data(), n, 1e-3, out.data());
    if (k % 10 != 0) continue;
    for (int node : liver->surface().nodes) {
      const Eigen::Vector3d x = liver->liver_contacts().deformed(node);
      for (std::size_t w = 0; w < rigids.size(); ++w) {
        const rigid::ClosestPoint c = rigids[w].second->closest_point(x, 0.02);
        if (c.found && c.distance < 0) deepest[w] = std::max(deepest[w], -c.distance);
      }
    }
  }
  nlohmann::json stats;
  organ->add_stats(stats);
  const nlohmann::json* walls = nullptr;
  const nlohmann::json* obstacles = nullptr;
  for (const nlohmann::json& o : stats["organs"]) {
    if (o.contains("walls")) walls = &o["walls"];
    if (o.contains("intestine")) obstacles = &o["intestine"]["obstacles"];
  }
  ASSERT_NE(walls, nullptr) << stats.dump(2);
  ASSERT_NE(obstacles, nullptr) << stats.dump(2);
  std::cout << "[lift] liver: " << walls->dump() << "\n[lift] bowel: " << obstacles->dump() << "\n";
  for (std::size_t w = 0; w < rigids.size(); ++w) {
    std::cout << "[lift] the liver's deepest surface node in '" << rigids[w].first << "': " << deepest[w] * 1e3
              << " mm\n";
    EXPECT_LT(deepest[w], 1e-3) << "the liver into '" << rigids[w].first << "'";
  }
  ASSERT_EQ(walls->size(), rigids.size());
  int ribs_ticks = 0;
  for (const nlohmann::json& w : *walls) {
    EXPECT_LE(w["max_penetration_mm"].get<double>(), 1.0) << w.dump();
    EXPECT_EQ(w["rows_dropped"].get<int>(), 0) << w.dump();
    if (w["organ"] == "ribs") ribs_ticks = w["contact_ticks"].get<int>();
  }
  EXPECT_GT(ribs_ticks, 100) << "the lifted edge must reach the ribs";
  int bowel_rigid = 0;
  for (const nlohmann::json& o : *obstacles) {
    for (const auto& r : rigids)
      if (o["organ"] == r.first) ++bowel_rigid;
    EXPECT_LE(o["max_penetration_mm"].get<double>(), 1.0) << o.dump();
  }
  EXPECT_EQ(bowel_rigid, 3);
}

}  // namespace
}  // namespace surgsim
