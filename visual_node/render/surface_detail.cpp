#include "render/surface_detail.h"

#include <algorithm>
#include <cmath>

namespace surgsim {
namespace {

// A 32-bit integer hash (lowbias32, Wellons) of the cell corner: the lattice value in [0, 1].
float lattice(std::int32_t x, std::int32_t y, std::int32_t z, std::uint32_t seed) {
  std::uint32_t h = seed ^ (static_cast<std::uint32_t>(x) * 0x8da6b343u) ^
                    (static_cast<std::uint32_t>(y) * 0xd8163841u) ^ (static_cast<std::uint32_t>(z) * 0xcb1ab31fu);
  h ^= h >> 16;
  h *= 0x7feb352du;
  h ^= h >> 15;
  h *= 0x846ca68bu;
  h ^= h >> 16;
  return static_cast<float>(h >> 8) * (1.0f / 16777215.0f);
}

float smooth(float t) { return t * t * (3.0f - 2.0f * t); }

// Three octaves of value noise, in [0, 1].
float fractal(const Eigen::Vector3f& p, std::uint32_t seed) {
  return (4.0f * value_noise(p, seed) + 2.0f * value_noise(2.03f * p, seed + 1u) + value_noise(4.01f * p, seed + 2u)) /
         7.0f;
}

}  // namespace

float value_noise(const Eigen::Vector3f& p, std::uint32_t seed) {
  const Eigen::Vector3f f = p.array().floor();
  const auto cx = static_cast<std::int32_t>(f.x()), cy = static_cast<std::int32_t>(f.y()),
             cz = static_cast<std::int32_t>(f.z());
  const float tx = smooth(p.x() - f.x()), ty = smooth(p.y() - f.y()), tz = smooth(p.z() - f.z());
  float v[2][2];
  for (int j = 0; j < 2; ++j) {
    for (int k = 0; k < 2; ++k) {
      const float a = lattice(cx, cy + j, cz + k, seed), b = lattice(cx + 1, cy + j, cz + k, seed);
      v[j][k] = a + tx * (b - a);
    }
  }
  const float y0 = v[0][0] + ty * (v[1][0] - v[0][0]);
  const float y1 = v[0][1] + ty * (v[1][1] - v[0][1]);
  return y0 + tz * (y1 - y0);
}

Eigen::MatrixX3f surface_tint(const Eigen::MatrixX3f& rest, const SurfaceDetail& d) {
  Eigen::MatrixX3f tint(rest.rows(), 3);
  for (Eigen::Index v = 0; v < rest.rows(); ++v) {
    const Eigen::Vector3f p = rest.row(v).transpose();
    // Mottling: the brightness, and each channel a little on its own.
    const float m = 1.0f + d.mottle * (2.0f * fractal(d.scale * p, d.seed) - 1.0f);
    Eigen::Vector3f t;
    for (int c = 0; c < 3; ++c) {
      t[c] = m * (1.0f + d.hue * (2.0f * value_noise(1.7f * d.scale * p, d.seed + 11u + static_cast<std::uint32_t>(c)) -
                                  1.0f));
    }
    // Streaks: where a second noise crosses one half (a thin ridge of 1 - |2 n - 1|).
    if (d.streaks > 0.0f) {
      const float ridge = 1.0f - std::abs(2.0f * fractal(d.streak_scale * p, d.seed + 23u) - 1.0f);
      const float s = d.streaks * smooth(std::clamp((ridge - 0.9f) / 0.08f, 0.0f, 1.0f));
      t = t + s * (t.cwiseProduct(d.streak_rgb) - t);
    }
    tint.row(v) = t.transpose();
  }
  return tint;
}

void blend_tint(Eigen::MatrixX3f& tint, const Eigen::VectorXf& weight, const Eigen::Vector3f& factor) {
  for (Eigen::Index v = 0; v < tint.rows() && v < weight.size(); ++v) {
    const float w = std::clamp(weight[v], 0.0f, 1.0f);
    tint.row(v) =
        tint.row(v).cwiseProduct(Eigen::RowVector3f::Ones() + w * (factor.transpose() - Eigen::RowVector3f::Ones()));
  }
}

}  // namespace surgsim
