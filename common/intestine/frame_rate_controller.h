// Guaranteed frame rate for the intestine rendering (Raghupathi et al. 2004, eq. 15; DESIGN.md 4.4).
//
//   eps_{k+1} = eps_k + alpha (f0 - f_k)
//   rho_{k+1} = rho_k + beta (eps_{k+1} - eps_k)
//   n_{k+1}   = floor(rho_{k+1})
// with f_k the measured frame rate (Hz) of frame k and f0 the target. As printed, a frame rate below the target
// (f0 - f_k > 0) raises rho, so for the loop to be a negative feedback n must count levels of detail REMOVED: n = 0
// draws the finest level. The controller therefore returns lod = lod_max - n, clamped to [lod_min, lod_max], and keeps
// rho inside [0, lod_max - lod_min + 1) so that it does not wind up while the LOD is pinned at a bound. Since
// rho_{k+1} - rho_k = alpha beta (f0 - f_k), this is an integral controller of gain alpha beta per Hz per frame
// (5e-4 with the paper's alpha = 1e-4, beta = 5: a 20 Hz error moves one level in 100 frames).
// With a discrete LOD the frame rate cannot settle exactly on f0: the LOD alternates between the two levels around
// it and the mean frame rate converges to f0 (as a sigma-delta modulator).
// Run phase only: update() is a few flops, no allocation.
#pragma once

namespace surgsim::intestine {

struct FrameRateParams {
  double target_hz = 50.0;  // f0
  double alpha = 1e-4;      // paper
  double beta = 5.0;        // paper
  int lod_min = 0;
  int lod_max = 6;          // kTubeMaxLod
  int initial_lod = 6;
};

class FrameRateController {
 public:
  /// Throws surgsim::Error on target <= 0, alpha or beta <= 0, or an empty LOD range.
  explicit FrameRateController(const FrameRateParams& params);

  /// Feeds the measured frame rate (Hz) of the last frame; returns the LOD to draw next. A non-finite or
  /// non-positive measurement is ignored (the LOD stays).
  int update(double measured_hz) noexcept;
  /// Same from a frame time (s): f_k = 1 / frame_time.
  int update_from_frame_time(double seconds) noexcept;

  int lod() const { return lod_; }
  double eps() const { return eps_; }
  double rho() const { return rho_; }
  int levels_removed() const { return n_; }
  const FrameRateParams& params() const { return params_; }
  void reset() noexcept;

 private:
  FrameRateParams params_;
  double eps_ = 0;
  double rho_ = 0;
  int n_ = 0;
  int lod_ = 0;
};

}  // namespace surgsim::intestine
