// Procedural surface detail without textures or per-fragment noise: each vertex gets a colour factor (a tint) computed
// once at load time from deterministic 3D value noise of its rest position, which the renderer interpolates across
// the triangles (Renderer::draw_surface with a tint). The picture is fill-bound on llvmpipe: the fragment shader stays
// the plain lit one, and the detail costs nothing per frame.
#pragma once
#include <Eigen/Core>
#include <cstdint>

namespace surgsim {

/// Value noise in [0, 1] at `p`: lattice values from an integer hash of the cell corner (and `seed`), blended with
/// smoothstep weights. Deterministic (the same on every host); period 2^32 cells.
float value_noise(const Eigen::Vector3f& p, std::uint32_t seed = 0);

/// What a surface's detail looks like.
struct SurfaceDetail {
  float scale = 40.0f;         // 1/m: about this many mottles a metre (the finest octave has 4x as many)
  float mottle = 0.12f;        // brightness varies by +-mottle
  float hue = 0.04f;           // and each channel a little on its own (+-hue)
  float streaks = 0.0f;        // 0..1: how strongly thin streaks (ridges of a second noise: vessels, fibres) show
  float streak_scale = 25.0f;  // 1/m
  Eigen::Vector3f streak_rgb = Eigen::Vector3f(0.75f, 0.5f, 0.55f);  // factor along a streak (darker, redder)
  std::uint32_t seed = 0;
};

/// The tint of each vertex at rest (`rest`: #V x 3, m): #V x 3 factors of the surface colour, near 1.
Eigen::MatrixX3f surface_tint(const Eigen::MatrixX3f& rest, const SurfaceDetail& detail);

/// `tint` (#V x 3) multiplied by `factor` at the vertices where `weight` (#V, 0..1) is 1, by a mix of 1 and `factor`
/// where it is between (e.g. a region of another tissue in the organ: its colour over the organ's).
void blend_tint(Eigen::MatrixX3f& tint, const Eigen::VectorXf& weight, const Eigen::Vector3f& factor);

}  // namespace surgsim
