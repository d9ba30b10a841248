// Scenes with an `organs:` list (scene/scene.h): each organ's model, keys and placement, rigid surfaces, the errors
// naming file, line and key, and the hash (a single-organ scene keeps its own).
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include "core/error.h"
#include "scene/scene.h"
#include "support/error_test_util.h"
#include "support/test_files.h"

using namespace surgsim::core;
using namespace surgsim::scene;

namespace surgsim {
namespace {

namespace fs = std::filesystem;

fs::path test_dir() { return test::fresh_test_dir("scene_organs_test_"); }

std::string write(const fs::path& path, const std::string& text) { return test::write_file(path, text); }

// The message of the Error load_scene throws, or "" if it loaded.
std::string load_error(const std::string& path) {
  return test::error_of([&] { load_scene(path); });
}

// A unit square in z = 0 as two triangles, counter-clockwise seen from +z (consistent), and the same with its second
// triangle flipped (the shared edge then runs the same way in both: no side to push out to).
const char* const kSquareObj = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 1 3 4\n";
const char* const kFlippedObj = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 1 4 3\n";

const std::string kThreeOrgans =
    "name: field\n"                                                    // 1
    "tools:\n"                                                         // 2
    "  - {name: probe, trocar: [0.03, 0, 0.2]}\n"                      // 3
    "  - {name: grasper, trocar: [-0.03, 0, 0.2], force_limit: 5}\n"   // 4
    "organs:\n"                                                        // 5
    "  - name: liver\n"                                                // 6
    "    model: liver\n"                                               // 7
    "    mesh: {generate: liver, target_nodes: 800}\n"                 // 8
    "    material: {young_modulus: 4000}\n"                            // 9
    "    fixed: {plane: {point: [0, 0, -0.025], normal: [0, 0, -1]}}\n"  // 10
    "    placement: {translation: [0.01, 0.02, 0.03], rotation_deg: [0, 0, 90]}\n"  // 11
    "  - name: bowel\n"                                                // 12
    "    model: intestine\n"                                           // 13
    "    intestine: {axis_origin: [0, 0, 0], axis_direction: [1, 0, 0]}\n"  // 14
    "    placement: {translation: [0, -0.1, 0], rotation_deg: [0, 0, 90]}\n"  // 15
    "  - name: wall\n"                                                 // 16
    "    model: rigid\n"                                               // 17
    "    rigid: {generate: dome, size: [0.2, 0.15, 0.12], open_z: 0, cavity: true, stiffness: 1500}\n";  // 18

TEST(SceneOrgans, ListGivesEachOrganItsModelKeysAndPlacement) {
  const fs::path dir = test_dir();
  const Scene s = load_scene(write(dir / "field.yaml", kThreeOrgans));
  EXPECT_TRUE(s.organ_list());
  EXPECT_EQ(s.model, "organs");
  ASSERT_EQ(s.organs.size(), 3u);
  EXPECT_EQ(s.organs[0].name, "liver");
  EXPECT_EQ(s.organs[0].model, "liver");
  EXPECT_EQ(s.organs[0].line, 6);
  EXPECT_EQ(s.organs[0].key, "organs[0]");
  EXPECT_EQ(s.organs[0].mesh.generate, "liver");
  EXPECT_EQ(s.organs[0].mesh.target_nodes, 800);
  EXPECT_DOUBLE_EQ(s.organs[0].material.young_modulus, 4000);
  // Rotation of 90 degrees about z: the organ's x axis is the scene's y.
  const auto& p = s.organs[0].placement;
  EXPECT_TRUE(p.rotation.isApprox(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix(), 1e-15));
  EXPECT_TRUE(p.to_world(Eigen::Vector3d(1, 0, 0)).isApprox(Eigen::Vector3d(0.01, 1.02, 0.03), 1e-12));
  EXPECT_TRUE(p.to_organ(p.to_world(Eigen::Vector3d(0.3, -0.2, 0.1))).isApprox(Eigen::Vector3d(0.3, -0.2, 0.1), 1e-14));
  // The fixed region stays in the organ's frame: a node at the organ's (0, 0, -0.03) is fixed wherever it is placed.
  const auto& fixed = s.organs[0].fixed;
  EXPECT_TRUE(fixed.fixes(-1, p.to_world(Eigen::Vector3d(0, 0, -0.03))));
  EXPECT_FALSE(fixed.fixes(-1, p.to_world(Eigen::Vector3d(0, 0, 0.0))));
  // Scene z = -0.02 is above the plane in the scene's frame but 5 cm down in the organ's (placed 3 cm up).
  EXPECT_TRUE(fixed.fixes(-1, Eigen::Vector3d(0, 0, -0.02)));
  EXPECT_EQ(s.organs[1].model, "intestine");
  EXPECT_DOUBLE_EQ(s.organs[1].intestine.params.probe_force_limit, 8.0);  // instrument 0's clamp
  EXPECT_EQ(s.organs[2].model, "rigid");
  EXPECT_EQ(s.organs[2].rigid.generate, "dome");
  EXPECT_TRUE(s.organs[2].rigid.cavity);
  EXPECT_DOUBLE_EQ(s.organs[2].rigid.stiffness, 1500);
  EXPECT_DOUBLE_EQ(s.organs[2].rigid.damping, 15.0);  // the default
  EXPECT_TRUE(s.organs[2].placement.identity());
  ASSERT_EQ(s.tools.size(), 2u);
}

TEST(SceneOrgans, OrganSceneIsTheSingleOrganViewInTheScenesFrame) {
  const fs::path dir = test_dir();
  const Scene s = load_scene(write(dir / "field.yaml", kThreeOrgans));
  const Scene liver = s.organ_scene(0);
  EXPECT_EQ(liver.model, "liver");
  EXPECT_FALSE(liver.organ_list());
  EXPECT_EQ(liver.mesh.target_nodes, 800);
  EXPECT_TRUE(liver.placement.rotation.isApprox(s.organs[0].placement.rotation, 0.0));
  EXPECT_EQ(liver.tools.size(), 2u);
  ASSERT_EQ(liver.organs.size(), 1u);
  EXPECT_EQ(liver.organs[0].name, "liver");
  // The intestine's axis, written along the organ's x, runs along the scene's y after the 90 degree turn.
  const Scene bowel = s.organ_scene(1);
  EXPECT_EQ(bowel.model, "intestine");
  EXPECT_TRUE(bowel.intestine.params.axis_direction.isApprox(Eigen::Vector3d::UnitY(), 1e-12));
  EXPECT_TRUE(bowel.intestine.params.axis_origin.isApprox(Eigen::Vector3d(0, -0.1, 0), 1e-12));
  const Scene wall = s.organ_scene(2);
  EXPECT_EQ(wall.model, "rigid");
  EXPECT_EQ(wall.rigid.generate, "dome");
  EXPECT_THROW(s.organ_scene(3), Error);
}

TEST(SceneOrgans, SingleOrganFormIsOneOrganNamedAfterTheScene) {
  const fs::path dir = test_dir();
  const Scene s = load_scene(write(dir / "one.yaml", "name: solo\nmesh: {generate: liver}\nmaterial: {young_modulus: "
                                                     "2500}\n"));
  EXPECT_FALSE(s.organ_list());
  ASSERT_EQ(s.organs.size(), 1u);
  EXPECT_EQ(s.organs[0].name, "solo");
  EXPECT_EQ(s.organs[0].model, "liver");
  EXPECT_DOUBLE_EQ(s.organs[0].material.young_modulus, 2500);
  EXPECT_TRUE(s.organs[0].placement.identity());
  // organ_scene(0) of a single-organ scene is the scene itself, hash included.
  EXPECT_EQ(s.organ_scene(0).hash(), s.hash());
}

TEST(SceneOrgans, RigidSurfaceFromAFile) {
  const fs::path dir = test_dir();
  write(dir / "wall.obj", kSquareObj);
  const Scene s = load_scene(write(dir / "f.yaml", "name: f\norgans:\n  - {name: wall, model: rigid, rigid: {file: "
                                                   "wall.obj, damping: 0}}\n"));
  ASSERT_EQ(s.organs.size(), 1u);
  EXPECT_EQ(s.organs[0].rigid.file, (dir / "wall.obj").lexically_normal().string());
  EXPECT_DOUBLE_EQ(s.organs[0].rigid.damping, 0.0);
}

TEST(SceneOrgans, HashSeesEveryOrganKeyButNotTheVisualSettings) {
  const fs::path dir = test_dir();
  const std::uint64_t h0 = load_scene(write(dir / "a.yaml", kThreeOrgans)).hash();
  EXPECT_EQ(h0, load_scene(write(dir / "a2.yaml", kThreeOrgans)).hash());
  EXPECT_EQ(h0, load_scene(write(dir / "v.yaml", kThreeOrgans + "visual: {width: 320}\n"))
                    .hash());
  const auto changed = [&](const std::string& from, const std::string& to, const char* file) {
    std::string text = kThreeOrgans;
    const std::size_t at = text.find(from);
    EXPECT_NE(at, std::string::npos) << from;
    text.replace(at, from.size(), to);
    return load_scene(write(dir / file, text)).hash();
  };
  EXPECT_NE(h0, changed("translation: [0.01, 0.02, 0.03]", "translation: [0.01, 0.02, 0.031]", "t.yaml"));
  EXPECT_NE(h0, changed("rotation_deg: [0, 0, 90]", "rotation_deg: [0, 1, 90]", "r.yaml"));
  EXPECT_NE(h0, changed("name: bowel", "name: gut", "n.yaml"));
  EXPECT_NE(h0, changed("stiffness: 1500", "stiffness: 1600", "k.yaml"));
  EXPECT_NE(h0, changed("cavity: true", "cavity: false", "c.yaml"));
  EXPECT_NE(h0, changed("young_modulus: 4000", "young_modulus: 4100", "e.yaml"));
  EXPECT_NE(h0, changed("axis_direction: [1, 0, 0]", "axis_direction: [0, 1, 0]", "i.yaml"));
}

struct OrganErrorCase {
  const char* name;
  std::string yaml;
  int line;
  std::string must_contain;
  std::string also = "";
};
std::ostream& operator<<(std::ostream& os, const OrganErrorCase& c) { return os << c.name; }
class SceneOrganError : public ::testing::TestWithParam<OrganErrorCase> {};

TEST_P(SceneOrganError, NamesFileLineAndKey) {
  const OrganErrorCase& c = GetParam();
  const fs::path dir = test_dir();
  write(dir / "square.obj", kSquareObj);
  write(dir / "flipped.obj", kFlippedObj);
  write(dir / "empty.obj", "v 0 0 0\n");
  write(dir / "mesh.stl", "solid x\n");
  const std::string path = write(dir / "bad_scene.yaml", c.yaml);
  const std::string msg = load_error(path);
  ASSERT_FALSE(msg.empty()) << "no error for:\n" << c.yaml;
  EXPECT_NE(msg.find("bad_scene.yaml:" + std::to_string(c.line) + ":"), std::string::npos) << msg;
  EXPECT_NE(msg.find(c.must_contain), std::string::npos) << msg;
  if (!c.also.empty()) {
    EXPECT_NE(msg.find(c.also), std::string::npos) << msg;
  }
}

const std::string kList = "name: t\norgans:\n";  // 2 lines

INSTANTIATE_TEST_SUITE_P(
    Cases, SceneOrganError,
    ::testing::Values(
        OrganErrorCase{"NotAList", "name: t\norgans: {name: liver}\n", 2, "key 'organs': expected a list"},
        OrganErrorCase{"EmptyList", "name: t\norgans: []\n", 2, "key 'organs': lists 0 organs"},
        OrganErrorCase{"TooMany",
                       kList +
                           [] {
                             std::string s;
                             for (int i = 0; i <= kMaxOrgans; ++i) {
                               s += "  - {name: w" + std::to_string(i) + ", model: rigid, rigid: {generate: plane}}\n";
                             }
                             return s;
                           }(),
                       2, "lists 9 organs"},
        OrganErrorCase{"NoName", kList + "  - {model: liver, mesh: {generate: liver}}\n", 3,
                       "key 'organs[0].name': missing"},
        OrganErrorCase{"NoModel", kList + "  - {name: liver, mesh: {generate: liver}}\n", 3,
                       "key 'organs[0].model': missing", "liver | intestine | rigid"},
        OrganErrorCase{"UnknownModel", kList + "  - {name: kidney, model: kidney}\n", 3, "key 'organs[0].model'",
                       "unknown value 'kidney'"},
        OrganErrorCase{"LiverWithoutMesh", kList + "  - {name: liver, model: liver}\n", 3,
                       "key 'organs[0].mesh': missing"},
        OrganErrorCase{"TwoOrgansOneName",
                       kList + "  - {name: a, model: liver, mesh: {generate: liver}}\n" +
                           "  - {name: a, model: rigid, rigid: {generate: plane}}\n",
                       4, "key 'organs[1].name'", "also the name of the organ on line 3"},
        OrganErrorCase{"BadName", kList + "  - {name: 'my liver', model: liver, mesh: {generate: liver}}\n", 3,
                       "key 'organs[0].name'", "character ' '"},
        OrganErrorCase{"ModelKeyAtTopLevel",
                       "name: t\nmaterial: {young_modulus: 3000}\norgans:\n  - {name: w, model: "
                       "rigid, rigid: {generate: plane}}\n",
                       2, "key 'material'", "move it into the organ"},
        OrganErrorCase{"UnknownOrganKey", kList + "  - {name: w, model: rigid, rigid: {generate: plane}, shade: red}\n",
                       3, "key 'organs[0].shade': unknown key"},
        OrganErrorCase{"RigidWithoutSurface", kList + "  - {name: w, model: rigid}\n", 3,
                       "key 'organs[0].rigid': missing"},
        OrganErrorCase{"RigidWithMesh",
                       kList + "  - {name: w, model: rigid, mesh: {generate: liver}, rigid: {generate: "
                               "plane}}\n",
                       3, "key 'organs[0].mesh': is not read for model rigid"},
        OrganErrorCase{"RigidOnLiver",
                       kList + "  - {name: l, model: liver, mesh: {generate: liver}, rigid: {generate: "
                               "plane}}\n",
                       3, "key 'organs[0].rigid': is only read for 'model: rigid'"},
        OrganErrorCase{"RigidFileAndGenerate",
                       kList + "  - {name: w, model: rigid, rigid: {file: square.obj, generate: "
                               "plane}}\n",
                       3, "has both 'generate' and 'file'"},
        OrganErrorCase{"RigidUnknownGenerator", kList + "  - {name: w, model: rigid, rigid: {generate: sphere}}\n", 3,
                       "key 'organs[0].rigid.generate'", "unknown value 'sphere'"},
        OrganErrorCase{"RigidMissingFile", kList + "  - {name: w, model: rigid, rigid: {file: none.obj}}\n", 3,
                       "key 'organs[0].rigid.file'", "not found"},
        OrganErrorCase{"RigidNotObj", kList + "  - {name: w, model: rigid, rigid: {file: mesh.stl}}\n", 3,
                       "key 'organs[0].rigid.file'", "unsupported surface format '.stl'"},
        OrganErrorCase{"RigidInconsistentOrientation",
                       kList + "  - {name: w, model: rigid, rigid: {file: flipped.obj}}\n", 3,
                       "key 'organs[0].rigid.file'", "no consistent orientation"},
        OrganErrorCase{"RigidNoTriangles", kList + "  - {name: w, model: rigid, rigid: {file: empty.obj}}\n", 3,
                       "key 'organs[0].rigid.file'"},
        OrganErrorCase{"RigidZeroSize",
                       kList + "  - {name: w, model: rigid, rigid: {generate: box, size: [0.1, 0, 0.1]}}\n", 3,
                       "key 'organs[0].rigid.size'", "component 1 is 0"},
        OrganErrorCase{"RigidCountNotForDome",
                       kList + "  - {name: w, model: rigid, rigid: {generate: dome, count: 3}}\n", 3,
                       "key 'organs[0].rigid.count'", "only read for generate: ribs"},
        OrganErrorCase{"RigidStiffness",
                       kList + "  - {name: w, model: rigid, rigid: {generate: plane, stiffness: 0}}\n", 3,
                       "key 'organs[0].rigid.stiffness'", "out of range"},
        OrganErrorCase{"PlacementAngle",
                       kList + "  - {name: w, model: rigid, rigid: {generate: plane}, placement: {rotation_deg: [0, 0, "
                               "400]}}\n",
                       3, "key 'organs[0].placement.rotation_deg'", "[-360, 360]"},
        OrganErrorCase{
            "PlacementKey",
            kList + "  - {name: w, model: rigid, rigid: {generate: plane}, placement: {rotaton_deg: [0, 0, 1]}}\n", 3,
            "key 'organs[0].placement.rotaton_deg'", "did you mean 'rotation_deg'"},
        OrganErrorCase{"RigidInSingleForm", "name: t\nmodel: rigid\n", 2, "key 'model'", "unknown value 'rigid'"}),
    [](const ::testing::TestParamInfo<OrganErrorCase>& info) { return std::string(info.param.name); });

}  // namespace
}  // namespace surgsim
