// Marching cubes (Lorensen & Cline, SIGGRAPH 1987) on a binary voxel mask, watertight and oriented outward.
//
// The cube is the one of Lorensen & Cline: its corners are 8 neighbouring voxel centres, a vertex sits where an
// edge joins an inside and an outside corner (at the edge's midpoint: the mask is binary, so that is exactly on the
// face shared by the two voxels), and each of the 256 corner configurations gives triangles. Instead of a
// hand-typed 256-entry table (Lorensen-Cline's 15 cases extended by symmetry, as in P. Bourke's "Polygonising a
// scalar field", 1994, where a face with two diagonal inside corners is not always cut the same way in the two
// cubes sharing it: the cracks M. Duerst pointed out, Computer Graphics 22(5), 1988) the table is generated when
// first used from one face rule: on such an ambiguous face, the inside corners are separated (foreground
// 6-connected, as clean_mask assumes). A face's cut then depends on that face alone, so the two cubes sharing it
// always agree: the surface is closed and 2-manifold. Each configuration's face cuts are chained into loops and
// fanned into (loop size - 2) triangles, as many as the classic tables give, from a loop vertex none of whose
// diagonals lies on a cube face.
#pragma once
#include <cstdint>

#include "mesh/tri_surface.h"
#include "imaging/volume.h"

namespace surgsim::imaging {

/// The surface between the mask's inside and outside voxels, in the grid frame (m; see VoxelGrid): closed,
/// 2-manifold and counter-clockwise seen from outside (the mask is treated as padded with outside voxels, so an
/// organ touching the volume's border is closed there). One surface per 6-connected component (run clean_mask first
/// for a single one). Vertices are numbered in scan order: deterministic.
mesh::TriSurface marching_cubes(const VoxelMask& mask);

/// The generated table, for tests: for configuration `config` (bit c set when corner c, at (c & 1, c >> 1 & 1,
/// c >> 2 & 1), is inside), up to 5 triangles as cube-edge triples, terminated by -1 (16 entries).
const std::int8_t* marching_cubes_case(int config);

/// Cube edge `edge` (0..11) joins corners edge_corner(edge, 0) and edge_corner(edge, 1).
int marching_cubes_edge_corner(int edge, int end);

}  // namespace surgsim::imaging
