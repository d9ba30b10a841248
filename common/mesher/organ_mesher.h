// Generated organs (plate, cylinder, liver-shaped solid) tetrahedralized with Gmsh's C++ API, with a node-count
// control and an on-disk cache of .msh/.vtk files (keyed by spec and generator version, checksummed).
//
// Gmsh keeps global state and is not thread-safe: every function here that meshes takes a process-wide lock,
// initializes Gmsh, and finalizes it before returning. Do not call them while your own code holds a Gmsh session
// (gmsh::initialize without gmsh::finalize): the two would share, and then destroy, the same global model.
#pragma once
#include <iosfwd>
#include <string>
#include <vector>

#include "mesh/mesh.h"
#include "mesh/tri_surface.h"

namespace surgsim::mesher {

/// Node counts a spec may ask for (inclusive).
inline constexpr int kMinOrganNodes = 100;
inline constexpr int kMaxOrganNodes = 200000;

/// What to generate. Shapes (units m, z up):
///  - "plate":    0.20 x 0.20 x 0.01 box centred at the origin;
///  - "cylinder": radius 0.025, height 0.10, axis z, base at z = 0;
///  - "liver":    smooth lobed solid in about x [-0.13, 0.13], y [-0.08, 0.08], z [-0.036, 0.043]: large right
///                lobe (x > 0), thinner left lobe tapering towards -x, a notch on the front edge (y < 0) between
///                them, flat underside near z = -0.035; the top above (0.03, 0) is at z = 0.042.
struct OrganSpec {
  std::string shape;        // "liver" | "plate" | "cylinder"
  int target_nodes = 1500;  // wanted node count, kMinOrganNodes..kMaxOrganNodes; achieved within about +-20 %
};

/// How a mesh was obtained (filled by generate_organ when asked).
struct OrganMeshReport {
  int nodes = 0;              // achieved node count
  int tets = 0;               // achieved tetrahedron count
  int attempts = 0;           // Gmsh meshings: 1 + re-meshes for the node count (<= 2) or a flat tet (<= 2)
  double mesh_size = 0.0;     // m, the characteristic length of the kept attempt
  double min_quality = 0.0;   // worst tet's 6 sqrt(2) |V| / l_rms^3 (1 regular, 0 flat); about 0.2..0.3 here
  double seconds = 0.0;       // wall time of the whole generation, s
};

/// The shapes generate_organ knows, in a stable order.
const std::vector<std::string>& organ_shapes();

/// Throws surgsim::core::Error with a one-line reason if the shape is unknown or target_nodes is out of range.
void check_organ_spec(const OrganSpec& spec);

/// Meshes the organ with linear tetrahedra, with about spec.target_nodes nodes (within +-20 % for targets from 500
/// up: the characteristic length is chosen from the volume and area, then corrected by up to two re-meshes; below
/// about 300 nodes the plate and cylinder saturate, e.g. 131 and 110 nodes for 100).
/// Deterministic: the same spec gives a bit-identical mesh (one thread, fixed seed, no user Gmsh config files).
/// The result has been through validate_mesh (positively oriented, no degenerate tets, manifold boundary).
/// `progress`, if given, receives one line per meshing attempt and Gmsh's own log; otherwise Gmsh is silent.
/// Throws surgsim::core::Error on a bad spec or when Gmsh fails. Takes a process-wide lock (see the file comment).
mesh::TetMesh generate_organ(const OrganSpec& spec, std::ostream* progress = nullptr,
                             OrganMeshReport* report = nullptr);

/// Tetrahedralizes the solid a closed triangle surface bounds, keeping the surface's triangles as the mesh boundary
/// (Gmsh 3D Delaunay inside a discrete surface; no remeshing of the surface), with about `target_nodes` nodes: the
/// surface's vertices plus interior nodes at a characteristic length chosen, and corrected by up to two re-meshes,
/// like generate_organ's. The surface's triangles face outward (counter-clockwise seen from outside); it must be
/// closed, 2-manifold and free of self-intersections, and have fewer vertices than target_nodes
/// (closed_surface_nodes gives a good vertex count to reduce it to). The result has been through validate_mesh and
/// its boundary is exactly `surface.tris` (nodes renumbered). Deterministic. Throws surgsim::core::Error when Gmsh
/// fails or the input is unusable. Takes the process-wide Gmsh lock (see the file comment).
mesh::TetMesh mesh_closed_surface(const mesh::TriSurface& surface, int target_nodes, std::ostream* progress = nullptr,
                                  OrganMeshReport* report = nullptr);

/// Surface vertices of a quasi-uniform tetrahedral mesh with `target_nodes` nodes of a solid with this volume (m^3)
/// and area (m^2), by generate_organ's node-count model: the size to reduce a surface to before
/// mesh_closed_surface. 0 for non-positive inputs.
int closed_surface_nodes(double volume, double area, int target_nodes);

/// Version of what generate_organ makes: part of the cache key (the file name) and recorded in the cached file. Bump it
/// whenever generate_organ's output changes (shapes, sizing, Gmsh options), so that meshes cached by the older mesher
/// are generated again instead of used.
inline constexpr int kOrganMeshVersion = 1;

/// The cache path of a spec: `<cache_dir>/<shape>-<target_nodes>-g<generator>.msh`.
std::string organ_mesh_path(const OrganSpec& spec, const std::string& cache_dir, int generator = kOrganMeshVersion);

/// Why the cached mesh at `path` may not be used for `spec` ("" when it may). A cached .msh ends with a section
///   $SurgsimOrganMesh
///   generator <kOrganMeshVersion> gmsh <Gmsh version> shape <shape> nodes <target_nodes>
///   checksum <16 hex digits: core::Hasher (FNV-1a) of every byte of the file before this line>
///   $EndSurgsimOrganMesh
/// (Gmsh and read_mesh skip a section they do not know), so a truncated or altered file, one of another generator or
/// Gmsh version, or one made for another spec is refused. Never throws.
std::string cached_organ_mesh_problem(const std::string& path, const OrganSpec& spec);

/// What ensure_organ_mesh found in the cache and did.
struct OrganMeshCacheOutcome {
  bool generated = false;  // this call meshed and wrote the file (it was missing or refused)
  std::string rejected;    // why a cached file was refused (cached_organ_mesh_problem); "" if none was or it was used
};

/// Returns organ_mesh_path(spec, cache_dir), generating the mesh first if that file does not exist or is refused by
/// cached_organ_mesh_problem (a Gmsh v2.2 .msh with its $SurgsimOrganMesh section, and a VTK .vtk beside it; a refused
/// file is said on `progress`, then replaced). Files are written to a unique temporary name in cache_dir and renamed
/// into place, so a concurrent reader or a second process generating the same spec never sees a partial file.
/// Creates cache_dir if missing. Throws surgsim::core::Error on a bad spec or when the folder is not writable.
std::string ensure_organ_mesh(const OrganSpec& spec, const std::string& cache_dir, std::ostream* progress = nullptr,
                              OrganMeshCacheOutcome* outcome = nullptr);

}  // namespace surgsim::mesher
