#include "scene/scene.h"

#include <yaml-cpp/yaml.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <climits>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <iterator>
#include <limits>
#include <sstream>
#include <system_error>

#include "core/error.h"
#include "core/hash.h"

using namespace surgsim::core;
using namespace surgsim::mesh;
using namespace surgsim::tool;
using namespace surgsim::fem;
using namespace surgsim::compliance;
using namespace surgsim::nonlinear;
using namespace surgsim::intestine;

#ifndef SURGSIM_DEFAULT_CONFIG_DIR
#define SURGSIM_DEFAULT_CONFIG_DIR "config"
#endif

namespace surgsim::scene {

namespace fs = std::filesystem;

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// ---------------------------------------------------------------------------------------------------------------
// Small helpers: messages, key suggestions, shipped scene list.

std::string fmt(double v) {
  std::ostringstream os;
  os << v;
  return os.str();
}

std::string join(const std::vector<std::string>& items, const char* sep = ", ") {
  std::string out;
  for (std::size_t i = 0; i < items.size(); ++i) out += (i ? sep : "") + items[i];
  return out;
}

std::size_t edit_distance(const std::string& a, const std::string& b) {
  std::vector<std::size_t> row(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    std::size_t diag = row[0];
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t up = row[j];
      const bool same =
          std::tolower(static_cast<unsigned char>(a[i - 1])) == std::tolower(static_cast<unsigned char>(b[j - 1]));
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diag + (same ? 0 : 1)});
      diag = up;
    }
  }
  return row[b.size()];
}

// Sorted names of the *.yaml files in the shipped config folder ("liver", "plate", ...).
std::vector<std::string> shipped_scenes() {
  std::vector<std::string> names;
  std::error_code ec;
  for (fs::directory_iterator it(config_dir(), ec), end; !ec && it != end; it.increment(ec)) {
    if (it->path().extension() == ".yaml" && it->is_regular_file(ec)) names.push_back(it->path().stem().string());
  }
  std::sort(names.begin(), names.end());
  return names;
}

std::string shipped_list() {
  const auto names = shipped_scenes();
  return names.empty() ? "none found in " + config_dir() : join(names);
}

// An interval of admissible values; lo/hi may be infinite.
struct Range {
  double lo, hi;
  bool lo_open, hi_open;
  bool contains(double v) const { return (lo_open ? v > lo : v >= lo) && (hi_open ? v < hi : v <= hi); }
  std::string str() const {
    return std::string(lo_open ? "(" : "[") + fmt(lo) + ", " + fmt(hi) + (hi_open ? ")" : "]");
  }
};
Range closed(double lo, double hi) { return {lo, hi, false, false}; }
Range positive() { return {0, kInf, true, true}; }

// ---------------------------------------------------------------------------------------------------------------
// Reading a YAML tree with messages "FILE:LINE: key 'a.b': what (fix)".

// A value in the document with its dotted key path and its 1-based line.
struct Field {
  YAML::Node node;
  std::string key;
  int line = 1;
};

int line_of(const YAML::Node& n, int fallback) {
  const YAML::Mark m = n.Mark();
  return m.is_null() ? fallback : m.line + 1;
}

class Reader {
 public:
  Reader(std::string shown, fs::path dir) : shown_(std::move(shown)), dir_(std::move(dir)) {}

  [[noreturn]] void fail(int line, const std::string& key, const std::string& what, const std::string& fix) const {
    std::ostringstream os;
    os << shown_ << ":" << line << ": ";
    if (!key.empty()) os << "key '" << key << "': ";
    os << what;
    if (!fix.empty()) os << " (" << fix << ")";
    throw Error(os.str());
  }

  // The node's kind, for "expected X, got Y".
  static std::string kind(const YAML::Node& n) {
    switch (n.Type()) {
      case YAML::NodeType::Sequence:
        return "a list";
      case YAML::NodeType::Map:
        return "a map";
      case YAML::NodeType::Null:
        return "nothing";
      default:
        return "'" + n.Scalar() + "'";
    }
  }

  // A plain (unquoted) scalar, else a type error saying what was expected.
  const std::string& plain_scalar(const Field& f, const std::string& expected, const std::string& fix) const {
    if (f.node.IsNull()) fail(f.line, f.key, "missing value, expected " + expected, fix);
    if (!f.node.IsScalar()) fail(f.line, f.key, "expected " + expected + ", got " + kind(f.node), fix);
    if (f.node.Tag() == "!") {
      fail(f.line, f.key, "expected " + expected + ", got the quoted string \"" + f.node.Scalar() + "\"",
           "write it without quotes");
    }
    return f.node.Scalar();
  }

  // "FILE:LINE: key 'a.b'", the prefix of fail()'s messages, for an error found once the mesh is loaded.
  std::string where(const Field& f) const { return shown_ + ":" + std::to_string(f.line) + ": key '" + f.key + "'"; }

  double number(const Field& f, const Range& range, const std::string& fix) const {
    std::string_view s = plain_scalar(f, "a number", fix);
    if (!s.empty() && s.front() == '+') s.remove_prefix(1);
    double v = 0;
    const auto r = std::from_chars(s.data(), s.data() + s.size(), v);
    const bool whole = !s.empty() && r.ptr == s.data() + s.size();
    std::string lower(s);
    for (char& c : lower) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    const bool yaml_special = lower == ".inf" || lower == "-.inf" || lower == ".nan";
    if (yaml_special || (whole && (r.ec == std::errc::result_out_of_range || !std::isfinite(v)))) {
      fail(f.line, f.key, f.node.Scalar() + " is not finite", fix);
    }
    if (!whole || r.ec != std::errc()) fail(f.line, f.key, "'" + f.node.Scalar() + "' is not a number", fix);
    if (!range.contains(v)) fail(f.line, f.key, f.node.Scalar() + " is out of range " + range.str(), fix);
    return v;
  }

  int integer(const Field& f, long long lo, long long hi, const std::string& fix) const {
    const std::string& s0 = plain_scalar(f, "an integer", fix);
    std::string_view s = s0;
    if (!s.empty() && s.front() == '+') s.remove_prefix(1);
    long long v = 0;
    const auto r = std::from_chars(s.data(), s.data() + s.size(), v);
    if (s.empty() || r.ptr != s.data() + s.size() || r.ec != std::errc()) {
      double d = 0;
      const auto rd = std::from_chars(s.data(), s.data() + s.size(), d);
      const bool is_real = !s.empty() && rd.ptr == s.data() + s.size() && rd.ec == std::errc();
      fail(f.line, f.key, is_real ? "expected an integer, got " + s0 : "'" + s0 + "' is not an integer", fix);
    }
    if (v < lo || v > hi) {
      fail(f.line, f.key, s0 + " is out of range [" + std::to_string(lo) + ", " + std::to_string(hi) + "]", fix);
    }
    return static_cast<int>(v);
  }

  bool boolean(const Field& f) const {
    const std::string fix = "write true or false";
    plain_scalar(f, "true or false", fix);
    bool b = false;
    if (!YAML::convert<bool>::decode(f.node, b)) fail(f.line, f.key, "'" + f.node.Scalar() + "' is not a boolean", fix);
    return b;
  }

  std::string text(const Field& f, const std::string& fix) const {
    if (f.node.IsNull()) fail(f.line, f.key, "missing value, expected a string", fix);
    if (!f.node.IsScalar()) fail(f.line, f.key, "expected a string, got " + kind(f.node), fix);
    if (f.node.Scalar().empty()) fail(f.line, f.key, "is empty", fix);
    return f.node.Scalar();
  }

  std::string one_of(const Field& f, std::initializer_list<const char*> allowed) const {
    std::vector<std::string> names(allowed.begin(), allowed.end());
    const std::string fix = "use one of: " + join(names);
    const std::string v = text(f, fix);
    if (std::find(names.begin(), names.end(), v) == names.end()) fail(f.line, f.key, "unknown value '" + v + "'", fix);
    return v;
  }

  Eigen::Vector3d vec3(const Field& f, const std::string& fix) const {
    const std::string want = "3 numbers [x, y, z]";
    if (f.node.IsNull()) fail(f.line, f.key, "missing value, expected " + want, fix);
    if (!f.node.IsSequence()) fail(f.line, f.key, "expected " + want + ", got " + kind(f.node), fix);
    if (f.node.size() != 3) {
      fail(f.line, f.key, "expected " + want + ", got a list of " + std::to_string(f.node.size()), fix);
    }
    Eigen::Vector3d v;
    for (int i = 0; i < 3; ++i) {
      const YAML::Node e = f.node[static_cast<std::size_t>(i)];
      v[i] = number({e, f.key + "[" + std::to_string(i) + "]", line_of(e, f.line)}, {-kInf, kInf, true, true}, fix);
    }
    return v;
  }

  // A non-zero vector, returned normalized.
  Eigen::Vector3d direction(const Field& f, const std::string& fix) const {
    const Eigen::Vector3d v = vec3(f, fix);
    if (!(v.norm() > 1e-12)) fail(f.line, f.key, "is the zero vector, a direction is needed", fix);
    return v.normalized();
  }

  // A file that must exist, relative to the scene's folder; returned absolute and normalized.
  std::string file(const Field& f, const std::string& what) const {
    const std::string fix = what + ", relative to the scene file's folder or absolute";
    const fs::path given(text(f, fix));
    const fs::path p = (given.is_absolute() ? given : dir_ / given).lexically_normal();
    std::error_code ec;
    if (!fs::exists(p, ec)) fail(f.line, f.key, "file '" + given.string() + "' not found at " + p.string(), fix);
    if (!fs::is_regular_file(p, ec)) fail(f.line, f.key, "'" + p.string() + "' is not a regular file", fix);
    return p.string();
  }

 private:
  std::string shown_;  // the scene path as given, for messages
  fs::path dir_;       // absolute folder of the scene file
};

// A YAML map whose keys are checked against a fixed set when it is opened. A null node is an empty map.
class Map {
 public:
  Map(const Reader& r, const Field& f, std::initializer_list<const char*> allowed) : r_(r), self_(f) {
    const std::vector<std::string> names(allowed.begin(), allowed.end());
    if (f.node.IsNull()) return;
    if (!f.node.IsMap()) {
      r.fail(f.line, f.key, "expected a map, got " + Reader::kind(f.node), "give keys: " + join(names));
    }
    for (auto it = f.node.begin(); it != f.node.end(); ++it) {
      const YAML::Node k = it->first;
      const int kline = line_of(k, f.line);
      if (!k.IsScalar()) r.fail(kline, f.key, "a key is " + Reader::kind(k) + ", keys must be plain names", "");
      const std::string& name = k.Scalar();
      const std::string path = f.key.empty() ? name : f.key + "." + name;
      if (std::find(names.begin(), names.end(), name) == names.end()) {
        std::string best;
        std::size_t best_d = std::numeric_limits<std::size_t>::max();
        for (const auto& n : names) {
          const std::size_t d = edit_distance(name, n);
          if (d < best_d) best_d = d, best = n;
        }
        const bool close = best_d <= std::max<std::size_t>(2, name.size() / 3);
        r.fail(kline, path, "unknown key",
               (close ? "did you mean '" + best + "'? " : std::string()) + "valid keys here: " + join(names));
      }
      for (const auto& e : entries_) {
        if (e.first == name) {
          r.fail(kline, path, "duplicate key (first given on line " + std::to_string(e.second.line) + ")",
                 "keep one of them");
        }
      }
      // Scalars report their own line; a block map or list starts below its key, so report the key's line.
      entries_.emplace_back(name, Field{it->second, path, it->second.IsScalar() ? line_of(it->second, kline) : kline});
    }
  }

  bool has(const char* k) const { return find(k) != nullptr; }
  const Field& at(const char* k) const {
    const Field* f = find(k);
    if (f == nullptr) r_.fail(self_.line, key(k), "missing", "");
    return *f;
  }
  std::string key(const char* k) const { return self_.key.empty() ? k : self_.key + "." + k; }
  const Field& self() const { return self_; }

 private:
  const Field* find(const char* k) const {
    for (const auto& e : entries_) {
      if (e.first == k) return &e.second;
    }
    return nullptr;
  }

  const Reader& r_;
  Field self_;
  std::vector<std::pair<std::string, Field>> entries_;
};

// ---------------------------------------------------------------------------------------------------------------
// Sections.

// A name of letters, digits, '_' or '-' (`what`: e.g. "the organ's name, e.g. liver"; `why` it must be so).
std::string read_name(const Reader& r, const Field& f, const std::string& what, const std::string& why) {
  const std::string name = r.text(f, what + " (letters, digits, '_' or '-')");
  for (const char ch : name) {
    if (!(std::isalnum(static_cast<unsigned char>(ch)) || ch == '_' || ch == '-')) {
      r.fail(f.line, f.key, "'" + name + "' has the character '" + std::string(1, ch) + "'",
             "use letters, digits, '_' or '-' (" + why + ")");
    }
  }
  return name;
}

MeshSource read_mesh_source(const Reader& r, const Field& f) {
  const Map m(r, f, {"generate", "file", "target_nodes"});
  MeshSource mesh;
  if (m.has("generate") && m.has("file")) {
    r.fail(m.at("file").line, f.key, "has both 'generate' and 'file'", "keep exactly one of them");
  }
  if (!m.has("generate") && !m.has("file")) {
    r.fail(f.line, f.key, "names no mesh", "add 'generate: liver' (liver | plate | cylinder) or 'file: meshes/x.msh'");
  }
  if (m.has("generate")) {
    mesh.generate = r.one_of(m.at("generate"), {"liver", "plate", "cylinder"});
    if (m.has("target_nodes")) {
      mesh.target_nodes =
          r.integer(m.at("target_nodes"), 100, 100000, "approximate node count; ~1500 runs in real time");
    }
  } else {
    if (m.has("target_nodes")) {
      r.fail(m.at("target_nodes").line, m.key("target_nodes"), "only applies to generated meshes",
             "remove it: a mesh file has its own node count");
    }
    const Field& ff = m.at("file");
    mesh.file = r.file(ff, "a tetrahedral mesh: Gmsh .msh (v1/v2/v4) or legacy VTK .vtk");
    const std::string ext = fs::path(mesh.file).extension().string();
    if (ext != ".msh" && ext != ".vtk") {
      r.fail(ff.line, ff.key, "unsupported mesh format '" + ext + "'", "use a Gmsh .msh or a legacy VTK .vtk file");
    }
  }
  return mesh;
}

std::pair<Eigen::Vector3d, Eigen::Vector3d> read_box(const Reader& r, const Field& f);

// A list of maps read one by one, each with its own key path "KEY[i]" and line.
template <class Read>
void read_list(const Reader& r, const Field& f, const std::string& fix, Read read) {
  if (!f.node.IsSequence()) r.fail(f.line, f.key, "expected a list, got " + Reader::kind(f.node), fix);
  for (std::size_t i = 0; i < f.node.size(); ++i) {
    const YAML::Node e = f.node[i];
    read(Field{e, f.key + "[" + std::to_string(i) + "]", line_of(e, f.line)});
  }
}

Ellipsoid read_ellipsoid(const Reader& r, const Field& f) {
  const Map m(r, f, {"center", "radii"});
  if (!m.has("center") || !m.has("radii")) {
    r.fail(f.line, f.key,
           std::string("needs both 'center' and 'radii' (missing '") + (m.has("center") ? "radii" : "center") + "')",
           "write {center: [x, y, z], radii: [rx, ry, rz]} in m, in the organ's own frame");
  }
  Ellipsoid e;
  e.center = r.vec3(m.at("center"), "the centre in m, [x, y, z]");
  e.radii = r.vec3(m.at("radii"), "the semi-axes along x, y, z in m, each > 0");
  for (int i = 0; i < 3; ++i) {
    if (!(e.radii[i] > 0)) {
      r.fail(m.at("radii").line, m.key("radii"), std::string("the ") + "xyz"[i] + " radius is " + fmt(e.radii[i]),
             "the semi-axes along x, y, z in m, each > 0");
    }
  }
  return e;
}

const char* const kMaterialFix = "use a value in [0, 0.5); soft tissue is nearly incompressible, e.g. 0.45";

// One entry of material.regions: a name, its material (Poisson's ratio defaults to the organ's) and where it is.
MaterialRegion read_material_region(const Reader& r, const Field& f, double base_poisson) {
  const Map m(r, f, {"name", "young_modulus", "poisson_ratio", "box", "boxes", "ellipsoid", "ellipsoids"});
  MaterialRegion region;
  if (!m.has("name")) r.fail(f.line, f.key + ".name", "missing", "name the region, e.g. name: gallbladder");
  region.name = read_name(r, m.at("name"), "the region's name, e.g. gallbladder", "it names the region in errors");
  region.where = r.where(f) + " (region '" + region.name + "')";
  if (!m.has("young_modulus")) {
    r.fail(f.line, m.key("young_modulus"), "missing", "the region's Young's modulus in Pa, e.g. young_modulus: 1000");
  }
  region.young_modulus = r.number(m.at("young_modulus"), positive(), "Young's modulus in Pa, > 0");
  region.poisson_ratio = base_poisson;
  if (m.has("poisson_ratio"))
    region.poisson_ratio = r.number(m.at("poisson_ratio"), {0, 0.5, false, true}, kMaterialFix);
  // Selectors in the order written: box, boxes, ellipsoid, ellipsoids (any of them holds an element).
  if (m.has("box")) region.boxes.push_back(read_box(r, m.at("box")));
  if (m.has("boxes")) {
    read_list(r, m.at("boxes"), "write a list of {min: [x, y, z], max: [x, y, z]}",
              [&](const Field& e) { region.boxes.push_back(read_box(r, e)); });
  }
  if (m.has("ellipsoid")) region.ellipsoids.push_back(read_ellipsoid(r, m.at("ellipsoid")));
  if (m.has("ellipsoids")) {
    read_list(r, m.at("ellipsoids"), "write a list of {center: [x, y, z], radii: [rx, ry, rz]}",
              [&](const Field& e) { region.ellipsoids.push_back(read_ellipsoid(r, e)); });
  }
  if (region.boxes.empty() && region.ellipsoids.empty()) {
    r.fail(f.line, f.key, "region '" + region.name + "' selects nothing",
           "give the elements it holds, by their centroid in the organ's own frame: box: {min: [x, y, z], max: [x, "
           "y, z]} and/or ellipsoid: {center: [x, y, z], radii: [rx, ry, rz]}");
  }
  return region;
}

Material read_material(const Reader& r, const Field& f, const std::string& model) {
  const Map m(r, f, {"young_modulus", "poisson_ratio", "regions"});
  Material mat;
  if (m.has("young_modulus")) {
    mat.young_modulus = r.number(m.at("young_modulus"), positive(), "Young's modulus in Pa, > 0; liver ~3000");
  }
  if (m.has("poisson_ratio")) mat.poisson_ratio = r.number(m.at("poisson_ratio"), {0, 0.5, false, true}, kMaterialFix);
  if (m.has("regions")) {
    const Field& rf = m.at("regions");
    if (model != "liver") {
      r.fail(rf.line, rf.key, "is only read for model liver (a FEM mesh)",
             "remove it: model " + model + " has no elements");
    }
    read_list(r, rf,
              "a list of regions, later ones over earlier ones, e.g. - {name: gallbladder, young_modulus: 1000, "
              "ellipsoid: {center: [x, y, z], radii: [rx, ry, rz]}}",
              [&](const Field& e) {
                MaterialRegion region = read_material_region(r, e, mat.poisson_ratio);
                for (const MaterialRegion& other : mat.regions) {
                  if (other.name == region.name) {
                    r.fail(e.line, e.key + ".name", "'" + region.name + "' is also the name of " + other.where,
                           "give each region its own name");
                  }
                }
                mat.regions.push_back(std::move(region));
              });
    if (mat.regions.empty()) r.fail(rf.line, rf.key, "is an empty list", "list at least one region, or remove the key");
  }
  return mat;
}

std::pair<Eigen::Vector3d, Eigen::Vector3d> read_box(const Reader& r, const Field& f) {
  const Map m(r, f, {"min", "max"});
  const std::string fix = "corner in m, [x, y, z]";
  if (!m.has("min") || !m.has("max")) {
    r.fail(f.line, f.key, std::string("needs both 'min' and 'max' (missing '") + (m.has("min") ? "max" : "min") + "')",
           "write {min: [x, y, z], max: [x, y, z]} in m");
  }
  const Eigen::Vector3d lo = r.vec3(m.at("min"), fix);
  const Eigen::Vector3d hi = r.vec3(m.at("max"), fix);
  for (int i = 0; i < 3; ++i) {
    if (!(lo[i] < hi[i])) {
      r.fail(m.at("max").line, m.key("max"),
             std::string("is not above min in ") + "xyz"[i] + " (" + fmt(hi[i]) + " <= " + fmt(lo[i]) + ")",
             "min must be < max in every component");
    }
  }
  return {lo, hi};
}

FixedRegion read_fixed(const Reader& r, const Field& f) {
  const Map m(r, f, {"nodes", "box", "boxes", "plane"});
  FixedRegion fixed;
  if (m.has("nodes")) {
    const Field& nf = m.at("nodes");
    const std::string fix = "a list of 0-based node indices, e.g. [0, 5, 7]";
    if (!nf.node.IsSequence()) r.fail(nf.line, nf.key, "expected a list, got " + Reader::kind(nf.node), fix);
    for (std::size_t i = 0; i < nf.node.size(); ++i) {
      const YAML::Node e = nf.node[i];
      fixed.nodes.push_back(
          r.integer({e, nf.key + "[" + std::to_string(i) + "]", line_of(e, nf.line)}, 0, INT_MAX, fix));
    }
  }
  if (m.has("box")) {
    const auto box = read_box(r, m.at("box"));
    fixed.boxes.push_back(box);
  }
  if (m.has("boxes")) {
    read_list(r, m.at("boxes"), "write a list of {min: [x, y, z], max: [x, y, z]}",
              [&](const Field& e) { fixed.boxes.push_back(read_box(r, e)); });
  }
  if (m.has("plane")) {
    const Map p(r, m.at("plane"), {"point", "normal"});
    if (!p.has("point") || !p.has("normal")) {
      r.fail(p.self().line, p.self().key,
             std::string("needs both 'point' and 'normal' (missing '") + (p.has("point") ? "normal" : "point") + "')",
             "write {point: [x, y, z], normal: [x, y, z]}; nodes with (x - point) . normal >= 0 are fixed");
    }
    fixed.has_plane = true;
    fixed.plane_point = r.vec3(p.at("point"), "a point on the plane in m");
    fixed.plane_normal = r.direction(p.at("normal"), "a non-zero normal pointing into the fixed side");
  }
  return fixed;
}

NonlinearSpec read_nonlinear(const Reader& r, const Field& f) {
  const Map m(r, f, {"displacement_curve", "force_curve", "degree"});
  NonlinearSpec nl;
  if (m.has("displacement_curve")) {
    nl.displacement_curve = r.file(m.at("displacement_curve"), "a CSV curve x,d_r in m");
  }
  if (m.has("force_curve")) nl.force_curve = r.file(m.at("force_curve"), "a CSV curve x,f in m, N");
  if (m.has("degree")) nl.degree = r.integer(m.at("degree"), 4, 10, "polynomial degree of the fitted law, 4..10");
  if (!nl.enabled()) {
    r.fail(f.line, f.key, "names no curve", "add displacement_curve and/or force_curve, or remove the section");
  }
  return nl;
}

LiverOptions read_liver(const Reader& r, const Field& f) {
  const Map m(r, f, {"deformation", "curves", "wall_reach"});
  LiverOptions o;
  if (m.has("deformation")) {
    const std::string d = r.one_of(m.at("deformation"), {"linear", "corotational", "multirate"});
    o.deformation = d == "corotational" ? LiverDeformation::kCorotational
                    : d == "multirate"  ? LiverDeformation::kMultirate
                                        : LiverDeformation::kLinear;
  }
  if (m.has("curves")) o.organ_curves = r.one_of(m.at("curves"), {"cylinder", "organ"}) == "organ";
  if (m.has("wall_reach")) {
    o.wall_reach = r.number(m.at("wall_reach"), closed(0.001, 0.5),
                            "m, 0.001..0.5: how far from a rigid organ at rest the liver's surface is held off it "
                            "(at least the furthest an instrument moves the liver)");
  }
  return o;
}

ToolSpec read_tool(const Reader& r, const Field& f) {
  const Map m(r, f,
              {"name", "trocar", "axis", "shaft_length", "shaft_radius", "shaft_points", "shaft_spacing", "jaw_length",
               "force_limit", "contact_capacity", "contact_model", "tip_radius", "friction"});
  ToolSpec t;
  if (m.has("name")) {
    t.name = read_name(r, m.at("name"), "the instrument's name, e.g. grasper",
                       "the name heads trajectory columns and stats keys");
  }
  if (m.has("trocar")) t.trocar = r.vec3(m.at("trocar"), "the fulcrum in world coordinates, m");
  if (m.has("axis")) t.axis = r.direction(m.at("axis"), "non-zero shaft direction into the body at pitch = yaw = 0");
  if (m.has("shaft_length")) t.shaft_length = r.number(m.at("shaft_length"), positive(), "length in m, > 0");
  if (m.has("shaft_radius")) t.shaft_radius = r.number(m.at("shaft_radius"), positive(), "radius in m, > 0");
  if (m.has("shaft_points")) {
    t.shaft_points = r.integer(m.at("shaft_points"), 1, 32, "contact points along the shaft, tip first, 1..32");
  }
  if (m.has("shaft_spacing")) t.shaft_spacing = r.number(m.at("shaft_spacing"), positive(), "spacing in m, > 0");
  if (m.has("jaw_length")) t.jaw_length = r.number(m.at("jaw_length"), positive(), "length in m, > 0");
  if (m.has("force_limit")) t.force_limit = r.number(m.at("force_limit"), positive(), "device force clamp in N, > 0");
  if (m.has("contact_capacity")) {
    t.contact_capacity = r.integer(m.at("contact_capacity"), 1, 64, "simultaneous contact nodes, 1..64");
  }
  if (m.has("contact_model")) {
    const std::string model = r.text(m.at("contact_model"), "patch | triangle");
    if (model == "patch") {
      t.contact_model = ContactModel::kPatch;
    } else if (model == "triangle") {
      t.contact_model = ContactModel::kTriangle;
    } else {
      r.fail(m.at("contact_model").line, m.key("contact_model"), "'" + model + "' is not a contact model",
             "use patch (smooth, tip of finite radius) or triangle (the paper's barycentric distribution)");
    }
  }
  if (m.has("tip_radius")) {
    t.tip_radius = r.number(m.at("tip_radius"), Range{0, 0.1, true, false},
                            "the instrument tip's own radius in m, e.g. 0.0025 for a 5 mm instrument, 0.005 for 10 mm");
  }
  if (m.has("friction")) t.friction = r.number(m.at("friction"), closed(0, 10), "Coulomb friction coefficient, 0..10");
  // The contact points must lie on the shaft.
  if ((t.shaft_points - 1) * t.shaft_spacing >= t.shaft_length) {
    const char* k = m.has("shaft_spacing") ? "shaft_spacing" : m.has("shaft_points") ? "shaft_points" : "shaft_length";
    r.fail(m.has(k) ? m.at(k).line : f.line, m.key(k),
           "(shaft_points - 1) * shaft_spacing = " + fmt((t.shaft_points - 1) * t.shaft_spacing) +
               " m does not fit in shaft_length = " + fmt(t.shaft_length) + " m",
           "use fewer points, a smaller spacing or a longer shaft");
  }
  return t;
}

HapticSpec read_haptic(const Reader& r, const Field& f) {
  const Map m(r, f, {"rate_hz", "passivity", "coupling_damping", "passivity_max_damping", "publish_hz"});
  HapticSpec h;
  if (m.has("rate_hz"))
    h.rate_hz = r.number(m.at("rate_hz"), closed(50, 20000), "haptic rate in Hz, >= 300 for stable force feedback");
  if (m.has("passivity")) h.passivity = r.boolean(m.at("passivity"));
  if (m.has("coupling_damping")) {
    h.coupling_damping = r.number(m.at("coupling_damping"), closed(0, 1000),
                                  "contact damper in N s/m, 0..1000 (0: none), e.g. 3");
  }
  if (m.has("passivity_max_damping")) {
    h.passivity_max_damping = r.number(m.at("passivity_max_damping"), {0, 1000, true, false},
                                       "largest damping of the passivity controller in N s/m, (0, 1000], e.g. 30");
  }
  if (m.has("publish_hz")) {
    const Field& b = m.at("publish_hz");
    h.publish_hz =
        r.number(b, closed(0, 20000), "contact frames and body states per second, 0 (every tick) or 1..rate_hz");
    if (h.publish_hz > 0 && (h.publish_hz < 1 || h.publish_hz > h.rate_hz)) {
      r.fail(b.line, m.key("publish_hz"),
             "publish_hz = " + fmt(h.publish_hz) + " is not 0 or within 1..rate_hz (" + fmt(h.rate_hz) + ")",
             "use 0 for every tick, or a rate up to the haptic rate, e.g. 4 x visual.rate_hz");
    }
  }
  return h;
}

// The camera: eye/target, or a laparoscope through a port (port/target/insertion/angle_deg/roll_deg).
Camera read_camera(const Reader& r, const Field& f) {
  const Map c(r, f, {"eye", "port", "target", "up", "fov_deg", "insertion", "angle_deg", "roll_deg"});
  Camera cam;
  const auto line_or = [&](const char* k) { return c.has(k) ? c.at(k).line : c.self().line; };
  if (c.has("eye") && c.has("port")) {
    r.fail(c.at("port").line, c.key("port"),
           "given together with 'eye' (line " + std::to_string(c.at("eye").line) + ")",
           "keep one: 'eye' for a free camera, 'port' for a laparoscope through the wall (its tip is the eye)");
  }
  cam.scope = c.has("port");
  if (!cam.scope) {
    for (const char* k : {"insertion", "angle_deg", "roll_deg"}) {
      if (c.has(k)) {
        r.fail(c.at(k).line, c.key(k), "is read only for a scope camera",
               "give 'port: [x, y, z]' instead of 'eye', or remove it");
      }
    }
  }
  if (c.has("eye")) cam.eye = r.vec3(c.at("eye"), "camera position in m");
  if (c.has("port")) cam.port = r.vec3(c.at("port"), "where the scope enters the abdominal wall, in m");
  if (c.has("target")) {
    cam.target =
        r.vec3(c.at("target"), cam.scope ? "the point the scope's shaft aims at, in m" : "point looked at, in m");
  } else if (cam.scope) {
    r.fail(c.self().line, c.key("target"), "missing",
           "a scope camera needs the point its shaft aims at: target: [x, y, z]");
  }
  if (c.has("up")) cam.up = r.direction(c.at("up"), "a non-zero up direction");
  if (c.has("fov_deg")) {
    cam.fov_deg = r.number(c.at("fov_deg"), {1, 170, true, true}, "vertical field of view in degrees");
  }
  if (cam.scope) {
    if (c.has("insertion")) {
      cam.insertion = r.number(c.at("insertion"), positive(), "m from the port to the scope's tip along its shaft");
    }
    if (c.has("angle_deg")) {
      cam.angle_deg = r.number(c.at("angle_deg"), closed(0, 75), "the scope's oblique angle in degrees: 0 or 30 usual");
    }
    if (c.has("roll_deg")) {
      cam.roll_deg = r.number(c.at("roll_deg"), closed(-360, 360), "the scope turned about its shaft, in degrees");
    }
    const Eigen::Vector3d shaft = cam.target - cam.port;
    if (!(shaft.norm() > 1e-9)) {
      r.fail(line_or("target"), c.key("target"), "equals the port",
             "the scope must aim at a point inside, away from the port");
    }
    if (!(cam.insertion < shaft.norm())) {
      r.fail(line_or("insertion"), c.key("insertion"),
             fmt(cam.insertion) + " m puts the tip at or past the target (" + fmt(shaft.norm()) + " m from the port)",
             "insert it less, or aim at a point farther in");
    }
    if (!(shaft.normalized().cross(cam.up).norm() > 1e-6)) {
      r.fail(line_or("up"), c.key("up"), "is parallel to the scope's shaft",
             "choose an up vector across target - port");
    }
    cam = scope_camera(cam);
  }
  const Eigen::Vector3d view = cam.target - cam.eye;
  if (!(view.norm() > 1e-9)) {
    r.fail(line_or("target"), c.key("target"), "equals the camera eye", "the eye must be away from the target");
  }
  if (!(view.normalized().cross(cam.up).norm() > 1e-6)) {
    r.fail(line_or("up"), c.key("up"), "is parallel to the viewing direction",
           "choose an up vector that is not along target - eye");
  }
  return cam;
}

// How the picture is drawn; `defaults` carries the light the camera implies.
RenderSpec read_render(const Reader& r, const Field& f, const RenderSpec& defaults) {
  const Map m(r, f, {"markers", "light", "falloff", "wet"});
  RenderSpec s = defaults;
  if (m.has("markers")) s.markers = r.boolean(m.at("markers"));
  if (m.has("light")) {
    s.light = r.one_of(m.at("light"), {"scope", "studio"}) == "scope" ? RenderSpec::Light::kScope
                                                                      : RenderSpec::Light::kStudio;
  }
  if (m.has("falloff")) {
    const Field& ff = m.at("falloff");
    if (s.light != RenderSpec::Light::kScope) {
      r.fail(ff.line, ff.key, "is read only for the scope light",
             "set light: scope (or a camera with 'port'), or remove it");
    }
    const std::string fix = "[a, b, c] of 1 / (a + b d + c d^2), d in m: each >= 0 and a > 0, e.g. [0.3, 0, 60]";
    s.falloff = r.vec3(ff, fix);
    if (!(s.falloff.minCoeff() >= 0.0) || !(s.falloff.x() > 0.0)) {
      r.fail(ff.line, ff.key, "has a negative term or a = 0 (the light infinite at the tip)", fix);
    }
  }
  if (m.has("wet")) s.wet = r.number(m.at("wet"), closed(0, 2), "wet speculars, 0 (matte) to 2, default 1");
  return s;
}

VisualSpec read_visual(const Reader& r, const Field& f) {
  const Map m(r, f,
              {"rate_hz", "width", "height", "camera", "render", "png_every", "vtk", "video", "surface", "target_fps",
               "stream_fps", "stream_quality", "min_render_scale"});
  VisualSpec v;
  if (m.has("rate_hz")) v.rate_hz = r.number(m.at("rate_hz"), closed(1, 1000), "frame rate in Hz, e.g. 50");
  if (m.has("target_fps")) {
    v.target_fps = r.number(m.at("target_fps"), closed(1, 1000),
                            "frame rate in Hz the intestine's level of detail is adapted to hold, e.g. 60");
  }
  if (m.has("stream_fps")) {
    v.stream_fps = r.number(m.at("stream_fps"), closed(0, 120),
                            "rate in Hz of the JPEG frames streamed on surgsim/frame for the web view; 0 = off");
  }
  if (m.has("stream_quality")) {
    v.stream_quality = r.integer(m.at("stream_quality"), 1, 100, "JPEG quality of the streamed frames, e.g. 75");
  }
  if (m.has("min_render_scale")) {
    v.min_render_scale = r.number(m.at("min_render_scale"), closed(0.25, 1),
                                  "lowest scale of the picture's resolution when frames overrun, e.g. 0.6; 1 = off");
  }
  if (m.has("width")) v.width = r.integer(m.at("width"), 16, 8192, "image width in pixels");
  if (m.has("height")) v.height = r.integer(m.at("height"), 16, 8192, "image height in pixels");
  if (m.has("png_every")) {
    v.png_every = r.integer(m.at("png_every"), 0, INT_MAX, "write every n-th frame as PNG; 0 = no PNG");
  }
  if (m.has("vtk")) v.vtk = r.boolean(m.at("vtk"));
  if (m.has("video")) v.video = r.boolean(m.at("video"));
  if (m.has("surface")) v.surface = r.file(m.at("surface"), "a finer visual surface mesh");
  if (m.has("camera")) v.camera = read_camera(r, m.at("camera"));
  v.render.light = v.camera.scope ? RenderSpec::Light::kScope : RenderSpec::Light::kStudio;
  if (m.has("render")) v.render = read_render(r, m.at("render"), v.render);
  return v;
}

IntestineSpec read_intestine(const Reader& r, const Field& f) {
  const Map m(r, f,
              {"length",
               "cylinder_radius",
               "folds",
               "angular_span",
               "fold_shape",
               "mesentery_taper",
               "axis_origin",
               "axis_direction",
               "columns",
               "rows",
               "intestine_radius",
               "mesentery_thickness",
               "intestine_node_mass",
               "mesentery_node_mass",
               "structural_stiffness",
               "shear_stiffness",
               "bending_stiffness",
               "spring_damping",
               "drag",
               "gravity",
               "integrator",
               "probe_radius",
               "probe_stiffness",
               "self_collisions",
               "detector",
               "random_pairs",
               "random_mesentery_pairs",
               "seed",
               "response_iterations",
               "contact_capacity",
               "obstacle_stiffness",
               "obstacle_capacity"});
  IntestineSpec spec;
  intestine::IntestineParams& p = spec.params;
  const Range non_negative{0, kInf, false, true};
  const auto read_number = [&](const char* k, double& out, const Range& range, const char* fix) {
    if (m.has(k)) out = r.number(m.at(k), range, fix);
  };

  // Rest shape.
  read_number("length", p.length, positive(), "arc length of the intestine in m, e.g. 4.0");
  read_number("cylinder_radius", p.cylinder_radius, positive(), "radius in m of the cylinder around the vessel, e.g. 0.15");
  if (m.has("folds")) p.folds = r.integer(m.at("folds"), 1, 100, "periods of the folded sine, e.g. 5");
  read_number("angular_span", p.angular_span, {0, 2 * 3.14159265358979323846, true, false},
           "angle in rad covered around the vessel, < 2 pi keeps the ends apart");
  read_number("fold_shape", p.fold_shape, closed(0, 2), "0 a plain sine, 1 vertical legs and round crests");
  read_number("mesentery_taper", p.mesentery_taper, closed(0, 0.45),
              "fraction of the length at each end over which the mesentery narrows to the vessel, 0..0.45 (0: none)");
  if (m.has("axis_origin")) p.axis_origin = r.vec3(m.at("axis_origin"), "centre of the curve on the vessel, m");
  if (m.has("axis_direction")) p.axis_direction = r.direction(m.at("axis_direction"), "non-zero vessel direction");
  if (m.has("columns")) {
    p.columns = r.integer(m.at("columns"), 4, intestine::kMaxIntestineNodes, "masses along the intestine, e.g. 100");
  }
  if (m.has("rows")) p.rows = r.integer(m.at("rows"), 2, intestine::kMaxIntestineNodes / 4, "masses across, e.g. 4");
  if (p.rows * p.columns > intestine::kMaxIntestineNodes) {
    const char* k = m.has("columns") ? "columns" : "rows";
    r.fail(m.at(k).line, m.key(k),
           "rows x columns = " + std::to_string(p.rows * p.columns) + " masses exceed " +
               std::to_string(intestine::kMaxIntestineNodes),
           "a BodyState carries at most " + std::to_string(intestine::kMaxIntestineNodes) + " positions");
  }
  read_number("intestine_radius", p.intestine_radius, positive(), "tube radius in m, e.g. 0.02");
  read_number("mesentery_thickness", p.mesentery_thickness, non_negative, "membrane thickness in m, e.g. 0.01");
  if (!(p.length > p.cylinder_radius * p.angular_span)) {
    const char* k = m.has("length") ? "length" : m.has("cylinder_radius") ? "cylinder_radius" : "angular_span";
    r.fail(m.has(k) ? m.at(k).line : f.line, m.key(k),
           "length " + fmt(p.length) + " m does not exceed the arc the curve covers (cylinder_radius x angular_span = " +
               fmt(p.cylinder_radius * p.angular_span) + " m)",
           "a longer intestine, a smaller cylinder or span: the folds need room");
  }

  // Masses and springs.
  read_number("intestine_node_mass", p.intestine_node_mass, positive(), "kg per intestine node, e.g. 0.012");
  read_number("mesentery_node_mass", p.mesentery_node_mass, positive(), "kg per mesentery node, e.g. 0.004");
  read_number("structural_stiffness", p.structural_stiffness, non_negative, "N/m, e.g. 300");
  read_number("shear_stiffness", p.shear_stiffness, non_negative, "N/m, e.g. 100");
  read_number("bending_stiffness", p.bending_stiffness, non_negative, "N/m, e.g. 30");
  read_number("spring_damping", p.spring_damping, non_negative, "N s/m along every spring, e.g. 0.1");
  read_number("drag", p.drag, non_negative, "1/s, viscous drag of the surrounding medium, e.g. 2");
  if (m.has("gravity")) p.gravity = r.vec3(m.at("gravity"), "acceleration in m/s^2, e.g. [0, 0, -9.81]");
  if (m.has("integrator")) {
    p.integrator = r.one_of(m.at("integrator"), {"implicit_euler", "symplectic_euler"}) == "implicit_euler"
                       ? intestine::Integrator::kImplicitEuler
                       : intestine::Integrator::kSymplecticEuler;
  }

  // Probe and collisions.
  read_number("probe_radius", spec.probe_radius, positive(), "radius in m of the sphere at the tool tip, e.g. 0.01");
  read_number("probe_stiffness", p.probe_stiffness, non_negative, "penalty stiffness of the probe contact in N/m");
  if (m.has("self_collisions")) p.self_collisions = r.boolean(m.at("self_collisions"));
  // The self-collision detector: stochastic (the paper's, the default) or broad_phase (the exact box
  // hierarchy: every contact, and faster on the shipped scene; intestine_bench tables 1 and 3b).
  if (m.has("detector")) {
    p.detector = r.one_of(m.at("detector"), {"broad_phase", "stochastic"}) == "stochastic"
                     ? intestine::CollisionDetector::kStochastic
                     : intestine::CollisionDetector::kBroadPhase;
  }
  if (m.has("random_pairs")) {
    p.detection.random_pairs = r.integer(m.at("random_pairs"), 0, 100000, "new pairs drawn per step (n), e.g. 10");
  }
  if (m.has("random_mesentery_pairs")) {
    p.detection.random_mesentery_pairs =
        r.integer(m.at("random_mesentery_pairs"), 0, 100000, "new intestine-mesentery pairs per step, e.g. 10");
  }
  if (m.has("seed")) p.detection.seed = r.integer(m.at("seed"), 1, INT_MAX, "seed of the random pairs, >= 1");
  if (m.has("response_iterations")) {
    p.response.iterations = r.integer(m.at("response_iterations"), 0, 100, "sweeps of the collision response, e.g. 4");
  }
  if (m.has("contact_capacity")) {
    p.contact_capacity = r.integer(m.at("contact_capacity"), 1, 100000, "self-collision contacts per step");
  }
  // The other organs of a field (rigid ones): the body rests on them.
  read_number("obstacle_stiffness", p.obstacle_stiffness, non_negative,
              "penalty stiffness in N/m of a node on another organ, e.g. 2000 (0: passes through them)");
  if (m.has("obstacle_capacity")) {
    p.obstacle_capacity = r.integer(m.at("obstacle_capacity"), 0, 100000, "node contacts on other organs per step");
  }
  return spec;
}

mesh::Placement read_placement(const Reader& r, const Field& f) {
  const Map m(r, f, {"translation", "rotation_deg"});
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  Eigen::Vector3d deg = Eigen::Vector3d::Zero();
  if (m.has("translation")) t = r.vec3(m.at("translation"), "the organ's origin in the scene, m");
  if (m.has("rotation_deg")) {
    deg = r.vec3(m.at("rotation_deg"), "angles in degrees about the organ's x, then y, then z axis");
    for (int i = 0; i < 3; ++i) {
      if (std::abs(deg[i]) > 360) {
        r.fail(m.at("rotation_deg").line, m.key("rotation_deg"), fmt(deg[i]) + " is out of range [-360, 360]",
               "angles in degrees about the organ's x, then y, then z axis");
      }
    }
  }
  return mesh::Placement::from_euler_deg(t, deg);
}

// Whether a .obj surface gives a side to push out to: every edge used by at most two triangles, in opposite
// directions (a consistent orientation), with finite vertices. Open surfaces (a patch of wall) are allowed.
void check_rigid_surface_file(const Reader& r, const Field& f, const std::string& path) {
  TriSurface surface;
  try {
    surface = read_obj(path);
  } catch (const Error& e) {
    r.fail(f.line, f.key, std::string("cannot be read: ") + e.what(), "give a Wavefront .obj triangle surface");
  }
  if (surface.tris.rows() == 0) r.fail(f.line, f.key, "'" + path + "' has no triangles", "give a triangle surface");
  if (!surface.vertices.allFinite()) {
    r.fail(f.line, f.key, "'" + path + "' has a non-finite vertex coordinate", "fix the file's 'v' lines");
  }
  const TriSurfaceTopology topo = tri_surface_topology(surface);
  if (topo.nonmanifold_edges > 0) {
    r.fail(f.line, f.key,
           "'" + path + "' has no consistent orientation: " + std::to_string(topo.nonmanifold_edges) +
               " edges are used twice in the same direction or by more than two triangles (no side to push out to)",
           "orient every triangle counter-clockwise seen from the free side (e.g. MeshLab: Re-Orient all faces "
           "coherently) and split non-manifold edges");
  }
}

RigidSpec read_rigid(const Reader& r, const Field& f) {
  const Map m(r, f, {"file", "generate", "size", "count", "arc_deg", "open_z", "cavity", "stiffness", "damping"});
  RigidSpec g;
  if (m.has("file") == m.has("generate")) {
    r.fail(m.has("file") ? m.at("file").line : f.line, f.key,
           m.has("file") ? "has both 'generate' and 'file'" : "names no surface",
           "keep exactly one: 'file: wall.obj' (a triangle surface) or 'generate: plane | box | tube | dome | ribs'");
  }
  const auto only_for = [&](const char* key, std::initializer_list<const char*> generators) {
    if (!m.has(key)) return;
    for (const char* g2 : generators) {
      if (g.generate == g2) return;
    }
    std::vector<std::string> names(generators.begin(), generators.end());
    r.fail(m.at(key).line, m.key(key), "is only read for generate: " + join(names, " | "), "remove it");
  };
  if (m.has("file")) {
    g.file = r.file(m.at("file"), "a Wavefront .obj triangle surface, counter-clockwise seen from the free side");
    const std::string ext = fs::path(g.file).extension().string();
    if (ext != ".obj") {
      r.fail(m.at("file").line, m.key("file"), "unsupported surface format '" + ext + "'", "use a Wavefront .obj file");
    }
    check_rigid_surface_file(r, m.at("file"), g.file);
    for (const char* key : {"size", "count", "arc_deg", "open_z"}) {
      if (m.has(key)) r.fail(m.at(key).line, m.key(key), "only applies to generated surfaces", "remove it");
    }
  } else {
    g.generate = r.one_of(m.at("generate"), {"plane", "box", "tube", "dome", "ribs"});
    if (m.has("size")) {
      g.size = r.vec3(m.at("size"),
                      "m: plane [x, y, 0]; box [x, y, z]; tube [radius, length, 0]; dome [rx, ry, rz]; ribs [arc "
                      "radius, spacing, bar radius]");
      const bool third_unused = g.generate == "plane" || g.generate == "tube";
      for (int i = 0; i < (third_unused ? 2 : 3); ++i) {
        if (!(g.size[i] > 0)) {
          r.fail(m.at("size").line, m.key("size"), "component " + std::to_string(i) + " is " + fmt(g.size[i]),
                 "every dimension the generator reads must be > 0 (m)");
        }
      }
    }
    only_for("count", {"ribs"});
    only_for("arc_deg", {"ribs"});
    only_for("open_z", {"dome"});
    if (m.has("count")) g.count = r.integer(m.at("count"), 1, 24, "rib arcs, 1..24");
    if (m.has("arc_deg")) g.arc_deg = r.number(m.at("arc_deg"), {0, 360, true, true}, "degrees, (0, 360)");
    if (m.has("open_z")) {
      g.dome_open_z = r.number(m.at("open_z"), {-1, 1, false, true},
                               "where the dome is cut, as a fraction of its z radius, [-1, 1): 0 = a half dome");
    }
  }
  if (m.has("cavity")) g.cavity = r.boolean(m.at("cavity"));
  if (m.has("stiffness")) {
    g.stiffness = r.number(m.at("stiffness"), {0, 1e5, true, false},
                           "the coupling's spring in N/m, (0, 100000]; a desktop device renders about 2000");
  }
  if (m.has("damping")) g.damping = r.number(m.at("damping"), closed(0, 1000), "the coupling's damper in N s/m, 0..1000");
  return g;
}

// The organ keys of a map: the scene's top level (the single-organ form, in_list false) or an entry of `organs:`.
OrganSpec read_organ(const Reader& r, const Map& m, const std::vector<ToolSpec>& tools, bool in_list) {
  OrganSpec o;
  o.key = m.self().key;
  o.line = m.self().line;
  if (m.has("model")) {
    o.model = in_list ? r.one_of(m.at("model"), {"liver", "intestine", "rigid"})
                      : r.one_of(m.at("model"), {"liver", "intestine"});
  }
  const auto not_for_model = [&](const char* key, const std::string& fix) {
    if (m.has(key)) {
      r.fail(m.at(key).line, m.key(key), "is not read for model " + o.model, fix);
    }
  };
  if (o.model == "rigid") {
    for (const char* key : {"mesh", "material", "fixed", "nonlinear"}) {
      not_for_model(key, "remove it: a rigid organ is a surface, given by 'rigid: {file: ... | generate: ...}'");
    }
    if (!m.has("rigid")) {
      r.fail(o.line, m.key("rigid"), "missing",
             "a rigid organ needs its surface: 'rigid: {generate: dome, size: [0.2, 0.15, 0.15], cavity: true}' or "
             "'rigid: {file: wall.obj}'");
    }
  }
  if (m.has("mesh")) {
    o.mesh = read_mesh_source(r, m.at("mesh"));
  } else if (o.model == "liver") {
    r.fail(o.line, m.key("mesh"), "missing",
           "add 'mesh: {generate: liver}' (liver | plate | cylinder) or 'mesh: {file: x.msh}'");
  }
  if (m.has("material")) o.material = read_material(r, m.at("material"), o.model);
  if (m.has("fixed")) o.fixed = read_fixed(r, m.at("fixed"));
  if (m.has("nonlinear")) o.nonlinear = read_nonlinear(r, m.at("nonlinear"));
  if (m.has("liver")) {
    const Field& lf = m.at("liver");
    if (o.model != "liver") {
      r.fail(lf.line, lf.key, "is only read for 'model: liver'", "set 'model: liver' or remove the section");
    }
    o.liver = read_liver(r, lf);
    if (o.liver.deformation == LiverDeformation::kCorotational && tools[0].contact_model != ContactModel::kPatch) {
      r.fail(lf.line, lf.key + ".deformation", "corotational needs the patch contact model",
             "set tool.contact_model: patch, or liver.deformation: linear");
    }
    if (o.liver.deformation == LiverDeformation::kMultirate && (o.liver.organ_curves || o.nonlinear.enabled())) {
      r.fail(lf.line, lf.key + ".deformation",
             "multirate is given together with a quasi non-linear law (liver.curves: organ or a nonlinear section)",
             "remove liver.curves / the nonlinear section: the multirate tracker is the non-linear model itself");
    }
    if (o.liver.organ_curves && o.nonlinear.enabled()) {
      r.fail(lf.line, lf.key + ".curves", "organ is given together with nonlinear: curve files",
             "remove the 'nonlinear' section (organ curves are computed from the organ itself) or set curves: cylinder");
    }
  }
  if (m.has("intestine")) {
    const Field& inf = m.at("intestine");
    if (o.model != "intestine") {
      r.fail(inf.line, inf.key, "is only read for 'model: intestine'", "set 'model: intestine' or remove the section");
    }
    o.intestine = read_intestine(r, inf);
  }
  // The display colour (either spelling).
  if (m.has("colour") && m.has("color")) {
    r.fail(m.at("color").line, m.key("color"),
           "given together with 'colour' (line " + std::to_string(m.at("colour").line) + ")", "keep one of them");
  }
  for (const char* k : {"colour", "color"}) {
    if (!m.has(k)) continue;
    const Field& cf = m.at(k);
    const std::string fix = "display RGB, each 0..1, e.g. [0.5, 0.16, 0.12]";
    o.colour = r.vec3(cf, fix);
    if (!(o.colour.minCoeff() >= 0.0 && o.colour.maxCoeff() <= 1.0))
      r.fail(cf.line, cf.key, "has a value outside [0, 1]", fix);
    o.has_colour = true;
  }
  o.intestine.params.probe_force_limit = tools[0].force_limit;  // the device clamp is the tool's (each probe its own)
  if (in_list) {
    if (m.has("rigid")) {
      if (o.model != "rigid") {
        r.fail(m.at("rigid").line, m.key("rigid"), "is only read for 'model: rigid'",
               "set 'model: rigid' or remove the section");
      }
      o.rigid = read_rigid(r, m.at("rigid"));
    }
    if (m.has("placement")) o.placement = read_placement(r, m.at("placement"));
    o.fixed.frame = o.placement;
    o.material.frame = o.placement;
  }
  return o;
}

// Hash helpers: -0.0 and 0.0 hash alike.
void hash_double(Hasher& h, double v) { h.value<double>(v == 0.0 ? 0.0 : v); }
void hash_vec(Hasher& h, const Eigen::Vector3d& v) {
  for (int i = 0; i < 3; ++i) hash_double(h, v[i]);
}
std::string file_name(const std::string& path) {
  return path.empty() ? std::string() : fs::path(path).filename().string();
}


}  // namespace

// -----------------------------------------------------------------------------------------------------------------


namespace {

// The organ's keys as the single-organ hash has always read them: mesh source, material, fixed set, law, options.
void hash_organ_keys(Hasher& h, const MeshSource& mesh, const Material& material, const FixedRegion& fixed,
                     const NonlinearSpec& nonlinear, const LiverOptions& liver) {
  // Mesh source: the file's name (not its folder, so two hosts agree), or the generator and its size.
  h.str(file_name(mesh.file));
  h.str(mesh.generate);
  h.value<std::int32_t>(mesh.generate.empty() ? 0 : mesh.target_nodes);

  hash_double(h, material.young_modulus);
  hash_double(h, material.poisson_ratio);

  // Fixed set: nodes, boxes (the single `box` key is the first entry of `boxes`), plane.
  h.value<std::uint64_t>(fixed.nodes.size());
  for (int n : fixed.nodes) h.value<std::int32_t>(n);
  h.value<std::uint64_t>(fixed.boxes.size());
  for (const auto& b : fixed.boxes) {
    hash_vec(h, b.first);
    hash_vec(h, b.second);
  }
  h.value<std::uint8_t>(fixed.has_plane);
  if (fixed.has_plane) {
    hash_vec(h, fixed.plane_point);
    hash_vec(h, fixed.plane_normal);
  }

  h.value<std::uint8_t>(nonlinear.enabled());
  if (nonlinear.enabled()) {
    h.str(file_name(nonlinear.displacement_curve));
    h.str(file_name(nonlinear.force_curve));
    h.value<std::int32_t>(nonlinear.degree);
  }

  // Material regions: hashed only when there are some, so older scenes keep their hash. Their frame is the organ's
  // placement, hashed with it.
  if (!material.regions.empty()) {
    h.str("material-regions");
    h.value<std::uint64_t>(material.regions.size());
    for (const MaterialRegion& r : material.regions) {
      h.str(r.name);
      hash_double(h, r.young_modulus);
      hash_double(h, r.poisson_ratio);
      h.value<std::uint64_t>(r.boxes.size());
      for (const auto& b : r.boxes) {
        hash_vec(h, b.first);
        hash_vec(h, b.second);
      }
      h.value<std::uint64_t>(r.ellipsoids.size());
      for (const Ellipsoid& e : r.ellipsoids) {
        hash_vec(h, e.center);
        hash_vec(h, e.radii);
      }
    }
  }

  // The liver's run-time model (liver.deformation, liver.curves): hashed only when not the default, so older scenes
  // keep their hash.
  if (!liver.defaults()) {
    h.str("liver-options");
    h.value<std::uint8_t>(static_cast<std::uint8_t>(liver.deformation));
    h.value<std::uint8_t>(liver.organ_curves);
  }
}

void hash_tools_and_haptic(Hasher& h, const std::vector<ToolSpec>& tools, const HapticSpec& haptic) {
  // Every instrument, in order (a second instrument changes the hash; one instrument hashes as the single
  // `tool:` key does, its name excepted, so scenes written for one instrument keep their hash).
  for (std::size_t i = 0; i < tools.size(); ++i) {
    const ToolSpec& tool = tools[i];
    if (i > 0) h.str(tool.name);
    hash_vec(h, tool.trocar);
    hash_vec(h, tool.axis);
    hash_double(h, tool.shaft_length);
    hash_double(h, tool.shaft_radius);
    h.value<std::int32_t>(tool.shaft_points);
    hash_double(h, tool.shaft_spacing);
    hash_double(h, tool.jaw_length);
    hash_double(h, tool.force_limit);
    h.value<std::int32_t>(tool.contact_capacity);
    h.value<std::int32_t>(static_cast<std::int32_t>(tool.contact_model));
    hash_double(h, tool.tip_radius);
    h.value<std::int32_t>(static_cast<std::int32_t>(tool.tip_model));
    hash_double(h, tool.friction);
  }

  hash_double(h, haptic.rate_hz);
  h.value<std::uint8_t>(haptic.passivity);
  hash_double(h, haptic.coupling_damping);
  hash_double(h, haptic.passivity_max_damping);
}

void hash_intestine(Hasher& h, const IntestineSpec& intestine) {
  const intestine::IntestineParams& p = intestine.params;
  for (double v : {p.length, p.cylinder_radius, p.angular_span, p.fold_shape, p.mesentery_taper, p.intestine_radius,
                   p.mesentery_thickness, p.intestine_node_mass, p.mesentery_node_mass, p.structural_stiffness,
                   p.shear_stiffness, p.bending_stiffness, p.spring_damping, p.drag, p.probe_stiffness,
                   p.probe_force_limit, p.detection.drop_factor, intestine.probe_radius}) {
    hash_double(h, v);
  }
  for (int v : {p.folds, p.columns, p.rows, p.probe_capacity, p.segment_exclusion, p.cell_exclusion,
                p.detection.random_pairs, p.detection.random_mesentery_pairs, p.detection.max_moves,
                p.detection.new_pair_moves, p.detection.zone_budget, p.detection.capacity, p.response.iterations,
                p.contact_capacity, static_cast<int>(p.integrator), static_cast<int>(p.self_collisions),
                static_cast<int>(p.detector), static_cast<int>(p.response.correct_velocity),
                static_cast<int>(p.response.correct_position)}) {
    h.value<std::int32_t>(v);
  }
  hash_vec(h, p.axis_origin);
  hash_vec(h, p.axis_direction);
  hash_vec(h, p.gravity);
  h.value<std::uint64_t>(p.detection.seed);
  // The other organs' contact (a field): hashed only when not the default, so older scenes keep their hash.
  const intestine::IntestineParams defaults;
  if (p.obstacle_stiffness != defaults.obstacle_stiffness || p.obstacle_capacity != defaults.obstacle_capacity) {
    h.str("obstacles");
    hash_double(h, p.obstacle_stiffness);
    h.value<std::int32_t>(p.obstacle_capacity);
  }
}

void hash_rigid(Hasher& h, const RigidSpec& g) {
  h.str(file_name(g.file));
  h.str(g.generate);
  hash_vec(h, g.size);
  h.value<std::int32_t>(g.count);
  hash_double(h, g.arc_deg);
  hash_double(h, g.dome_open_z);
  h.value<std::uint8_t>(g.cavity);
  hash_double(h, g.stiffness);
  hash_double(h, g.damping);
}

}  // namespace

std::uint64_t Scene::hash() const {
  Hasher h;
  if (!organ_list()) {
    // The single-organ form hashes exactly as before organ lists existed (caches and recordings keep matching).
    h.str("surgsim-scene-v1");
    h.str(model);
    hash_organ_keys(h, mesh, material, fixed, nonlinear, liver);
    hash_tools_and_haptic(h, tools, haptic);
    if (model == "intestine") hash_intestine(h, intestine);
    return h.digest();
  }
  h.str("surgsim-scene-v2");
  h.value<std::uint64_t>(organs.size());
  for (const OrganSpec& o : organs) {
    h.str(o.name);
    h.str(o.model);
    for (int i = 0; i < 9; ++i) hash_double(h, o.placement.rotation(i / 3, i % 3));
    hash_vec(h, o.placement.translation);
    if (o.model == "liver") hash_organ_keys(h, o.mesh, o.material, o.fixed, o.nonlinear, o.liver);
    if (o.model == "intestine") hash_intestine(h, o.intestine);
    if (o.model == "rigid") hash_rigid(h, o.rigid);
  }
  hash_tools_and_haptic(h, tools, haptic);
  return h.digest();
}

Camera scope_camera(const Camera& camera) {
  if (!camera.scope) return camera;
  constexpr double kDeg = 3.14159265358979323846 / 180.0;
  Camera c = camera;
  const Eigen::Vector3d shaft = (camera.target - camera.port).normalized();
  c.eye = camera.port + camera.insertion * shaft;
  // The side the oblique lens looks to: `up` across the shaft, turned by the roll about it.
  Eigen::Vector3d side = camera.up - camera.up.dot(shaft) * shaft;
  side = side.norm() > 1e-12 ? side.normalized() : shaft.unitOrthogonal();
  side = Eigen::AngleAxisd(camera.roll_deg * kDeg, shaft) * side;
  const double a = camera.angle_deg * kDeg;
  const Eigen::Vector3d view = std::cos(a) * shaft + std::sin(a) * side;
  c.target = c.eye + (camera.target - c.eye).norm() * view;
  return c;
}

Scene Scene::organ_scene(std::size_t i) const {
  if (i >= organs.size()) {
    throw_error(file, ": organ ", i, " asked for, the scene has ", organs.size());
  }
  const OrganSpec& o = organs[i];
  Scene s = *this;
  s.model = o.model;
  s.mesh = o.mesh;
  s.material = o.material;
  s.fixed = o.fixed;
  s.nonlinear = o.nonlinear;
  s.liver = o.liver;
  s.intestine = o.intestine;
  s.rigid = o.rigid;
  s.placement = o.placement;
  // The intestine's axis is written in the organ's frame: put it in the scene's.
  s.intestine.params.axis_origin = o.placement.to_world(o.intestine.params.axis_origin);
  s.intestine.params.axis_direction = o.placement.direction_to_world(o.intestine.params.axis_direction);
  s.organs = {o};
  return s;
}

Scene load_scene(const std::string& path) {
  // Read the file and parse the YAML.
  std::error_code ec;
  if (fs::is_directory(path, ec)) throw_error(path, ": is a folder, not a scene file (give the .yaml file)");
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    throw_error(path, ": cannot open scene file: ", std::strerror(errno),
                " (check the path, or give a shipped scene: ", shipped_list(), ")");
  }
  const std::string content((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const fs::path abs = fs::absolute(path, ec).lexically_normal();
  const Reader r(path, abs.parent_path());
  YAML::Node root;
  try {
    root = YAML::Load(content);
  } catch (const YAML::Exception& e) {
    // An unclosed bracket is reported at the end of input: name the last line that exists instead.
    const int lines = static_cast<int>(std::count(content.begin(), content.end(), '\n')) +
                      (!content.empty() && content.back() != '\n' ? 1 : 0);
    r.fail(e.mark.is_null() ? 1 : std::clamp(e.mark.line + 1, 1, std::max(1, lines)), "", "YAML syntax error: " + e.msg,
           "check indentation, the ':' after each key and matching brackets and quotes");
  }
  if (root.IsNull()) r.fail(1, "", "the scene is empty", "a scene needs at least 'name' and 'mesh'");
  if (!root.IsMap()) {
    r.fail(line_of(root, 1), "", "the scene must be a map of keys, got " + Reader::kind(root),
           "write 'name: ...', 'mesh: ...' etc. one per line");
  }

  const Map top(r, {root, "", 1},
                {"name", "model", "mesh", "material", "fixed", "nonlinear", "liver", "tool", "tools", "haptic",
                 "visual", "intestine", "trajectory", "organs", "colour", "color"});
  Scene s;
  s.file = abs.string();
  s.dir = abs.parent_path().string();

  if (!top.has("name")) r.fail(1, "name", "missing", "every scene needs a name, e.g. 'name: liver'");
  s.name = r.text(top.at("name"), "the scene's name, e.g. liver");

  if (top.has("tool") && top.has("tools")) {
    r.fail(top.at("tools").line, "tools", "given together with 'tool' (line " + std::to_string(top.at("tool").line) + ")",
           "keep one: 'tool:' for one instrument, or 'tools:' listing each instrument with its name");
  }
  if (top.has("tool")) s.tools = {read_tool(r, top.at("tool"))};
  if (top.has("tools")) {
    const Field& tf = top.at("tools");
    const std::string fix = "a list of 1.." + std::to_string(kMaxInstruments) +
                            " instruments, each a map like 'tool:' with its own name, e.g. - {name: grasper, trocar: "
                            "[0, 0, 0.2]}";
    if (!tf.node.IsSequence()) r.fail(tf.line, tf.key, "expected a list, got " + Reader::kind(tf.node), fix);
    if (tf.node.size() < 1 || tf.node.size() > static_cast<std::size_t>(kMaxInstruments)) {
      r.fail(tf.line, tf.key, "lists " + std::to_string(tf.node.size()) + " instruments", fix);
    }
    s.tools.clear();
    for (std::size_t i = 0; i < tf.node.size(); ++i) {
      const YAML::Node e = tf.node[i];
      const Field ef{e, tf.key + "[" + std::to_string(i) + "]", line_of(e, tf.line)};
      const Map em(r, ef, {"name", "trocar", "axis", "shaft_length", "shaft_radius", "shaft_points", "shaft_spacing",
                           "jaw_length", "force_limit", "contact_capacity", "contact_model", "tip_radius", "friction"});
      if (!em.has("name")) r.fail(ef.line, ef.key + ".name", "missing", "every instrument of 'tools:' needs a name");
      s.tools.push_back(read_tool(r, ef));
      for (std::size_t j = 0; j < i; ++j) {
        if (s.tools[j].name == s.tools[i].name) {
          r.fail(em.at("name").line, ef.key + ".name", "'" + s.tools[i].name + "' is also instrument " + std::to_string(j),
                 "give each instrument its own name");
        }
      }
      if (s.tools[i].contact_model != s.tools[0].contact_model) {
        r.fail(em.has("contact_model") ? em.at("contact_model").line : ef.line, ef.key + ".contact_model",
               "differs from instrument 0's: all contacts are solved together with one model",
               "give every instrument the same contact_model");
      }
    }
  }

  if (top.has("organs")) {
    // The list form: every organ's keys live in its entry, none at the top level.
    for (const char* key :
         {"model", "mesh", "material", "fixed", "nonlinear", "liver", "intestine", "colour", "color"}) {
      if (top.has(key)) {
        r.fail(top.at(key).line, key, "is given at the top level of a scene with 'organs:' (line " +
                                          std::to_string(top.at("organs").line) + ")",
               "move it into the organ it belongs to: each entry of 'organs:' has its own model, mesh, material, "
               "fixed, nonlinear, liver and intestine keys");
      }
    }
    const Field& of = top.at("organs");
    const std::string fix = "a list of 1.." + std::to_string(kMaxOrgans) +
                            " organs, each a map with its own name and model, e.g. - {name: liver, model: liver, mesh: "
                            "{generate: liver}}";
    if (!of.node.IsSequence()) r.fail(of.line, of.key, "expected a list, got " + Reader::kind(of.node), fix);
    if (of.node.size() < 1 || of.node.size() > static_cast<std::size_t>(kMaxOrgans)) {
      r.fail(of.line, of.key, "lists " + std::to_string(of.node.size()) + " organs", fix);
    }
    s.model = "organs";
    for (std::size_t i = 0; i < of.node.size(); ++i) {
      const YAML::Node e = of.node[i];
      const Field ef{e, of.key + "[" + std::to_string(i) + "]", line_of(e, of.line)};
      const Map em(r, ef,
                   {"name", "model", "mesh", "material", "fixed", "nonlinear", "liver", "intestine", "rigid",
                    "placement", "colour", "color"});
      if (!em.has("name")) {
        r.fail(ef.line, ef.key + ".name", "missing", "every organ of 'organs:' needs a name, e.g. name: liver");
      }
      if (!em.has("model")) {
        r.fail(ef.line, ef.key + ".model", "missing", "say what the organ is: model: liver | intestine | rigid");
      }
      OrganSpec o = read_organ(r, em, s.tools, true);
      o.name = read_name(r, em.at("name"), "the organ's name, e.g. liver", "the name heads stats keys and topics");
      for (const OrganSpec& other : s.organs) {
        if (other.name == o.name) {
          r.fail(em.at("name").line, em.key("name"),
                 "'" + o.name + "' is also the name of the organ on line " + std::to_string(other.line),
                 "give each organ its own name");
        }
      }
      s.organs.push_back(std::move(o));
    }
  } else {
    // The single-organ form: the organ's keys at the top level, the organ named after the scene.
    OrganSpec o = read_organ(r, top, s.tools, false);
    o.name = s.name;
    s.model = o.model;
    s.mesh = o.mesh;
    s.material = o.material;
    s.fixed = o.fixed;
    s.nonlinear = o.nonlinear;
    s.liver = o.liver;
    s.intestine = o.intestine;
    s.organs = {std::move(o)};
  }
  if (top.has("haptic")) s.haptic = read_haptic(r, top.at("haptic"));
  if (top.has("visual")) s.visual = read_visual(r, top.at("visual"));
  if (top.has("trajectory"))
    s.trajectory = r.file(top.at("trajectory"), "a tool trajectory CSV (surgsim-trajectory v1, or v2 with one column group per instrument)");
  return s;
}

std::string config_dir() {
  const char* env = std::getenv("SURGSIM_CONFIG_DIR");
  return env != nullptr && *env != '\0' ? std::string(env) : std::string(SURGSIM_DEFAULT_CONFIG_DIR);
}

std::string resolve_scene_path(const std::string& name_or_path) {
  if (name_or_path.empty()) throw_error("empty scene argument (give a scene file or one of: ", shipped_list(), ")");
  std::error_code ec;
  if (fs::is_regular_file(name_or_path, ec)) return name_or_path;

  // A bare name: look it up among the shipped scenes.
  const fs::path p(name_or_path);
  if (!p.has_parent_path()) {
    const fs::path candidate =
        fs::path(config_dir()) / (p.extension() == ".yaml" ? name_or_path : name_or_path + ".yaml");
    if (fs::is_regular_file(candidate, ec)) return candidate.string();
  }
  throw_error("scene '", name_or_path, "': no such file and no shipped scene of that name in ", config_dir(),
              " (shipped scenes: ", shipped_list(), "; or give the path of a scene .yaml)");
}

}  // namespace surgsim::scene
