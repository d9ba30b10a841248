// Material regions of a liver's mesh (heterogeneous tissue: `material.regions`): the keys, their errors naming file,
// line and key, the frame of a placed organ, the scene and tensor hashes (a scene without regions keeps its own), and
// the regions on the organ's own generated mesh.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "compliance/tensor_cache.h"
#include "core/error.h"
#include "fem/fem.h"
#include "mesher/scene_mesh.h"
#include "scene/scene.h"
#include "support/error_test_util.h"
#include "support/test_files.h"

using namespace surgsim::core;
using namespace surgsim::fem;
using namespace surgsim::scene;

namespace surgsim {
namespace {

namespace fs = std::filesystem;

fs::path test_dir() { return test::fresh_test_dir("scene_regions_test_"); }

std::string write(const fs::path& path, const std::string& text) { return test::write_file(path, text); }

// The message of the Error load_scene throws, or "" if it loaded.
std::string load_error(const std::string& path) {
  return test::error_of([&] { load_scene(path); });
}

const std::string kHead = "name: t\nmesh: {generate: liver}\n";  // 2 lines

// A liver with two regions (lines 3-10).
const std::string kTwoRegions = kHead +
                                "material:\n"                                                                     // 3
                                "  young_modulus: 3000\n"                                                         // 4
                                "  poisson_ratio: 0.4\n"                                                          // 5
                                "  regions:\n"                                                                    // 6
                                "    - name: gallbladder\n"                                                       // 7
                                "      young_modulus: 800\n"                                                      // 8
                                "      ellipsoid: {center: [-0.03, -0.04, -0.02], radii: [0.02, 0.04, 0.015]}\n"  // 9
                                "    - {name: vessel, young_modulus: 9000, poisson_ratio: 0.3, box: {min: [0, 0, 0], "
                                "max: [0.01, 0.02, 0.03]}, boxes: [{min: [0, 0, 0], max: [1, 1, 1]}], ellipsoids: "
                                "[{center: [0, 0, 0], radii: [1, 2, 3]}]}\n";  // 10

TEST(SceneRegions, KeysAreRead) {
  const Scene s = load_scene(write(test_dir() / "r.yaml", kTwoRegions));
  ASSERT_EQ(s.material.regions.size(), 2u);
  const MaterialRegion& g = s.material.regions[0];
  EXPECT_EQ(g.name, "gallbladder");
  EXPECT_EQ(g.young_modulus, 800);
  EXPECT_EQ(g.poisson_ratio, 0.4);  // the organ's, when not given
  EXPECT_TRUE(g.boxes.empty());
  ASSERT_EQ(g.ellipsoids.size(), 1u);
  EXPECT_EQ(g.ellipsoids[0].center, Eigen::Vector3d(-0.03, -0.04, -0.02));
  EXPECT_EQ(g.ellipsoids[0].radii, Eigen::Vector3d(0.02, 0.04, 0.015));
  EXPECT_NE(g.where.find("r.yaml:7: key 'material.regions[0]'"), std::string::npos) << g.where;
  const MaterialRegion& v = s.material.regions[1];
  EXPECT_EQ(v.name, "vessel");
  EXPECT_EQ(v.poisson_ratio, 0.3);
  ASSERT_EQ(v.boxes.size(), 2u);  // `box` first, then `boxes`
  EXPECT_EQ(v.boxes[0].second, Eigen::Vector3d(0.01, 0.02, 0.03));
  EXPECT_EQ(v.boxes[1].second, Eigen::Vector3d(1, 1, 1));
  ASSERT_EQ(v.ellipsoids.size(), 1u);
  EXPECT_EQ(v.ellipsoids[0].radii, Eigen::Vector3d(1, 2, 3));
  EXPECT_TRUE(s.material.frame.identity());
  EXPECT_EQ(s.organs[0].material.regions.size(), 2u);
}

TEST(SceneRegions, APlacedOrgansRegionsAreInItsOwnFrame) {
  const std::string yaml =
      "name: field\n"
      "organs:\n"
      "  - name: liver\n"
      "    model: liver\n"
      "    mesh: {generate: liver}\n"
      "    material: {regions: [{name: g, young_modulus: 900, box: {min: [0, 0, 0], max: [1, 1, 1]}}]}\n"
      "    placement: {translation: [0.1, 0.2, 0.3], rotation_deg: [0, 0, 90]}\n";
  const Scene s = load_scene(write(test_dir() / "p.yaml", yaml));
  const Scene liver = s.organ_scene(0);
  ASSERT_EQ(liver.material.regions.size(), 1u);
  EXPECT_EQ(liver.material.frame.translation, Eigen::Vector3d(0.1, 0.2, 0.3));
  EXPECT_TRUE(liver.material.frame.rotation.isApprox(liver.fixed.frame.rotation, 0));
  EXPECT_FALSE(liver.material.frame.identity());
}

struct RegionError {
  const char* name;
  std::string yaml;
  int line;
  std::string must_contain;
  std::string also;
};

class SceneRegionError : public ::testing::TestWithParam<RegionError> {};

TEST_P(SceneRegionError, NamesFileLineKeyAndFix) {
  const RegionError& c = GetParam();
  const std::string msg = load_error(write(test_dir() / "bad_scene.yaml", c.yaml));
  ASSERT_FALSE(msg.empty()) << "no error for:\n" << c.yaml;
  EXPECT_NE(msg.find("bad_scene.yaml:" + std::to_string(c.line) + ":"), std::string::npos) << msg;
  EXPECT_NE(msg.find(c.must_contain), std::string::npos) << msg;
  EXPECT_NE(msg.find(c.also), std::string::npos) << msg;
}

const std::string kRegions = kHead + "material:\n  regions:\n";  // 4 lines
const std::string kOk = "    - {name: a, young_modulus: 900, box: {min: [0, 0, 0], max: [1, 1, 1]}}\n";

INSTANTIATE_TEST_SUITE_P(
    Cases, SceneRegionError,
    ::testing::Values(
        RegionError{"UnknownKey", kRegions + "    - {name: a, young_modulus: 900, ellipsiod: {}}\n", 5,
                    "key 'material.regions[0].ellipsiod': unknown key", "did you mean 'ellipsoid'"},
        RegionError{"UnknownMaterialKey", kHead + "material: {region: []}\n", 3, "key 'material.region': unknown key",
                    "did you mean 'regions'"},
        RegionError{"NotAList", kHead + "material: {regions: {name: a}}\n", 3, "key 'material.regions'",
                    "expected a list, got a map"},
        RegionError{"EmptyList", kHead + "material: {regions: []}\n", 3, "key 'material.regions': is an empty list",
                    "remove the key"},
        RegionError{"MissingName", kRegions + "    - {young_modulus: 900, box: {min: [0, 0, 0], max: [1, 1, 1]}}\n", 5,
                    "key 'material.regions[0].name': missing", "name: gallbladder"},
        RegionError{"BadName", kRegions + "    - {name: 'gall bladder', young_modulus: 900}\n", 5,
                    "key 'material.regions[0].name'", "has the character ' '"},
        RegionError{"MissingModulus", kRegions + "    - {name: a, box: {min: [0, 0, 0], max: [1, 1, 1]}}\n", 5,
                    "key 'material.regions[0].young_modulus': missing", "Young's modulus in Pa"},
        RegionError{"BadModulus", kRegions + "    - {name: a, young_modulus: -5}\n", 5,
                    "key 'material.regions[0].young_modulus': -5 is out of range", "> 0"},
        RegionError{"IncompressibleRegion", kRegions + "    - {name: a, young_modulus: 900, poisson_ratio: 0.5}\n", 5,
                    "key 'material.regions[0].poisson_ratio': 0.5 is out of range", "[0, 0.5)"},
        RegionError{"NoSelector", kRegions + "    - {name: a, young_modulus: 900}\n", 5,
                    "key 'material.regions[0]': region 'a' selects nothing", "ellipsoid: {center"},
        RegionError{"BoxInverted",
                    kRegions + "    - {name: a, young_modulus: 900, box: {min: [0, 0, 1], max: [1, 1, 0]}}\n", 5,
                    "key 'material.regions[0].box.max': is not above min in z", "min must be < max"},
        RegionError{"EllipsoidRadius",
                    kRegions +
                        "    - {name: a, young_modulus: 900, ellipsoid: {center: [0, 0, 0], radii: [1, 0, 1]}}\n",
                    5, "key 'material.regions[0].ellipsoid.radii': the y radius is 0", "each > 0"},
        RegionError{"EllipsoidMissingRadii",
                    kRegions + "    - {name: a, young_modulus: 900, ellipsoid: {center: [0, 0, 0]}}\n", 5,
                    "key 'material.regions[0].ellipsoid': needs both 'center' and 'radii' (missing 'radii')",
                    "organ's own frame"},
        RegionError{"EllipsoidsNotAList",
                    kRegions + "    - {name: a, young_modulus: 900, ellipsoids: {center: [0, 0, 0]}}\n", 5,
                    "key 'material.regions[0].ellipsoids': expected a list", "radii: [rx, ry, rz]"},
        RegionError{"DuplicateName", kRegions + kOk + kOk, 6, "key 'material.regions[1].name': 'a' is also the name of",
                    "bad_scene.yaml:5: key 'material.regions[0]'"},
        RegionError{"Intestine", "name: t\nmodel: intestine\nmaterial: {regions: [{name: a}]}\n", 3,
                    "key 'material.regions': is only read for model liver", "remove it"}),
    [](const ::testing::TestParamInfo<RegionError>& i) { return std::string(i.param.name); });

TEST(SceneRegions, ARegionHoldingNoTetOfTheMeshIsAnErrorNamingItsLine) {
  const fs::path dir = test_dir();
  const std::string path = write(dir / "far.yaml", kHead +
                                                       "material:\n"
                                                       "  regions:\n"
                                                       "    - {name: far, young_modulus: 900, ellipsoid: {center: [1, "
                                                       "1, 1], radii: [0.01, 0.01, 0.01]}}\n");
  const Scene s = load_scene(path);  // the scene alone cannot tell: it has no mesh
  const mesh::TetMesh mesh = mesher::load_scene_mesh(s, SURGSIM_TEST_CACHE_DIR, nullptr);
  const std::string what = test::error_of([&] { element_materials(mesh, s.material, s.file); });
  EXPECT_NE(what.find("far.yaml:5: key 'material.regions[0]' (region 'far'): material region 'far' holds no element"),
            std::string::npos)
      << what;
  EXPECT_NE(what.find("organ's own frame"), std::string::npos) << what;
}

// The gallbladder of the issue on the shipped liver (config/abdomen.yaml's: generated, 1500 nodes, placed): a soft
// ellipsoid in the fossa under the right lobe, right of the front notch, its fundus at the front edge. It must hold
// a gallbladder's volume of tets (30-50 ml) on the underside, and change the liver's stiffness there.
TEST(SceneRegions, TheGallbladderLiesInTheFossaOfTheShippedLiver) {
  const std::string yaml =
      "name: field\n"
      "organs:\n"
      "  - name: liver\n"
      "    model: liver\n"
      "    mesh: {generate: liver, target_nodes: 1500}\n"
      "    material:\n"
      "      young_modulus: 3000.0\n"
      "      poisson_ratio: 0.45\n"
      "      regions:\n"
      "        - name: gallbladder\n"
      "          young_modulus: 750.0\n"
      "          ellipsoid: {center: [0.035, -0.04, -0.025], radii: [0.018, 0.04, 0.013]}\n"
      "    fixed:\n"
      "      plane: {point: [0, 0, -0.025], normal: [0, 0, -1]}\n"
      "    placement: {translation: [-0.03, 0.07, -0.043]}\n";
  const Scene liver = load_scene(write(test_dir() / "gallbladder.yaml", yaml)).organ_scene(0);
  const mesh::TetMesh mesh = mesher::load_scene_mesh(liver, SURGSIM_TEST_CACHE_DIR, nullptr);
  const ElementMaterials em = element_materials(mesh, liver.material, liver.file);
  int held = 0;
  double volume = 0;
  double top = -1;  // the highest centroid held, in the liver's own frame
  for (Eigen::Index t = 0; t < mesh.tets.rows(); ++t) {
    if (em.element[static_cast<std::size_t>(t)] != 1) continue;
    Eigen::Matrix3d e;
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (int a = 0; a < 3; ++a)
      e.col(a) = (mesh.nodes.row(mesh.tets(t, a + 1)) - mesh.nodes.row(mesh.tets(t, 0))).transpose();
    for (int a = 0; a < 4; ++a) c += mesh.nodes.row(mesh.tets(t, a)).transpose() / 4;
    ++held;
    volume += e.determinant() / 6;
    top = std::max(top, liver.material.frame.to_organ(c).z());
  }
  std::printf("gallbladder: %d of %d tets, %.1f cm^3, highest centroid z = %.3f m (organ frame)\n", held,
              static_cast<int>(mesh.tets.rows()), volume * 1e6, top);
  EXPECT_GT(volume, 25e-6);
  EXPECT_LT(volume, 50e-6);
  EXPECT_LT(top, 0.0);  // under the liver's mid-plane: on the underside, not through the lobe
  EXPECT_EQ(em.materials[1].young_modulus, 750.0);
  EXPECT_EQ(em.materials[1].poisson_ratio, 0.45);
}

// ---------------------------------------------------------------------------------------------------------------
// Hashes

TEST(SceneRegions, AScenesWithoutRegionsKeepTheirHashes) {
  // Taken from the scene and tensor hashes before regions existed (6ea914f).
  const fs::path dir = test_dir();
  EXPECT_EQ(load_scene(write(dir / "a.yaml",
                             "name: mini\nmesh: {generate: liver}\nmaterial: {young_modulus: 4000, "
                             "poisson_ratio: 0.4}\n"))
                .hash(),
            0x7761683854d016f1ULL);
  EXPECT_EQ(load_scene(write(dir / "b.yaml",
                             "name: two\ntool: {trocar: [0, 0, 0.2]}\norgans:\n  - {name: liver, model: liver, mesh: "
                             "{generate: liver}, material: {young_modulus: 2500}, placement: {translation: [0.1, 0, "
                             "0], rotation_deg: [0, 0, 30]}}\n"))
                .hash(),
            0xced3234b77e02e2bULL);
  EXPECT_EQ(compliance::material_hash(Material{4000, 0.4}), 0xd7bdb08cf633ee36ULL);
}

TEST(SceneRegions, ARegionsModulusOrSelectorChangesTheSceneAndTensorHashes) {
  const fs::path dir = test_dir();
  const auto scene = [&](const std::string& name, const std::string& region) {
    return load_scene(
        write(dir / (name + ".yaml"), kHead + "material: {young_modulus: 3000, regions: [" + region + "]}\n"));
  };
  const std::string base = "{name: g, young_modulus: 800, ellipsoid: {center: [0, 0, 0], radii: [0.01, 0.02, 0.03]}}";
  const Scene s0 = scene("s0", base);
  const Scene none = load_scene(write(dir / "none.yaml", kHead + "material: {young_modulus: 3000}\n"));
  EXPECT_NE(s0.hash(), none.hash());
  EXPECT_NE(compliance::material_hash(s0.material), compliance::material_hash(none.material));
  EXPECT_EQ(s0.hash(), scene("again", base).hash());  // deterministic
  EXPECT_EQ(compliance::material_hash(s0.material), compliance::material_hash(scene("again2", base).material));
  const std::string changed[] = {
      "{name: g, young_modulus: 801, ellipsoid: {center: [0, 0, 0], radii: [0.01, 0.02, 0.03]}}",
      "{name: g, young_modulus: 800, poisson_ratio: 0.3, ellipsoid: {center: [0, 0, 0], radii: [0.01, 0.02, 0.03]}}",
      "{name: g, young_modulus: 800, ellipsoid: {center: [0, 0.001, 0], radii: [0.01, 0.02, 0.03]}}",
      "{name: g, young_modulus: 800, ellipsoid: {center: [0, 0, 0], radii: [0.01, 0.02, 0.031]}}",
      "{name: g, young_modulus: 800, box: {min: [-0.01, -0.02, -0.03], max: [0.01, 0.02, 0.03]}}",
      base + ", {name: h, young_modulus: 800, box: {min: [0, 0, 0], max: [1, 1, 1]}}",
  };
  int i = 0;
  for (const std::string& c : changed) {
    const Scene s = scene("c" + std::to_string(i++), c);
    EXPECT_NE(s.hash(), s0.hash()) << c;
    EXPECT_NE(compliance::material_hash(s.material), compliance::material_hash(s0.material)) << c;
  }
  // The frame moves the regions over the mesh: part of the tensor hash.
  Material moved = s0.material;
  moved.frame.translation.x() = 0.01;
  EXPECT_NE(compliance::material_hash(moved), compliance::material_hash(s0.material));
}

}  // namespace
}  // namespace surgsim
