// Guaranteed frame rate for the intestine rendering (Raghupathi et al. 2004, eq. 15; docs/DESIGN.md, section 'Intestine
// rendering').
//
//   eps_{k+1} = eps_k + alpha e_k
//   rho_{k+1} = rho_k + beta (eps_{k+1} - eps_k)
//   n_{k+1}   = floor(rho_{k+1})
// with e_k the error of frame k against the target f0. As printed, e_k = f0 - f_k (Hz, f_k the measured frame rate),
// and a frame rate below the target raises rho, so for the loop to be a negative feedback n must count levels of
// detail REMOVED: n = 0 draws the finest level. The controller therefore returns lod = lod_max - n, clamped to
// [lod_min, lod_max], and keeps rho inside [0, lod_max - lod_min + 1) so that it does not wind up while the LOD is
// pinned at a bound. Since rho_{k+1} - rho_k = alpha beta e_k, this is an integral controller of gain alpha beta.
//
// Why the paper's law settles slowly: with e in Hz its gain is alpha beta = 5e-4 levels per Hz per frame, so
// a 10 Hz error moves one level in 200 frames (7 s at 30 Hz); the benchmark needed 74-174 frames, live the LOD stayed
// at 4-6 for a whole run. And a level's effect on the rate is not a fixed number of Hz: the tube's cost doubles per
// level, so the same Hz error means a whole level at 30 Hz and a fraction of one at 200 Hz; no single alpha suits
// every target. The default error is therefore the rate's ratio in octaves, e_k = log2(f0 / f_k) = log2(T_k / T0)
// (FrameRateError::kLog2Ratio): one level of a tube-dominated frame is about one octave of frame time, so alpha beta =
// 0.5 (alpha = 0.1, beta = 5) closes half of the gap in levels every frame whatever the target: a load step of 3x
// settles within 2-15 frames (bench section 5; tests), with margin below the gain at which the one frame of delay
// makes it overshoot. FrameRateError::kHz with alpha = 1e-4 is the paper's law
// as printed (FrameRateParams::paper).
//
// With a discrete LOD the frame rate cannot settle exactly on f0: the LOD alternates between the two levels around it
// (+-1 LOD, no wider) and the mean of the error converges to 0 (a sigma-delta modulator).
// Run phase only: update() is a few flops, no allocation.
#pragma once

namespace surgsim::intestine {

/// The error e_k fed to eq. 15.
enum class FrameRateError {
  kLog2Ratio,  // e = log2(f0 / f): octaves of frame time (default)
  kHz,         // e = f0 - f: the paper as printed
};

struct FrameRateParams {
  double target_hz = 50.0;  // f0
  FrameRateError error = FrameRateError::kLog2Ratio;
  double alpha = 0.1;       // per octave (kLog2Ratio); the paper's 1e-4 per Hz with kHz
  double beta = 5.0;        // paper
  int lod_min = 0;
  int lod_max = 6;          // kTubeMaxLod
  int initial_lod = 6;

  /// The paper's law and gains as printed (e in Hz, alpha = 1e-4, beta = 5), for comparison.
  static FrameRateParams paper(double target_hz) {
    FrameRateParams p;
    p.target_hz = target_hz;
    p.error = FrameRateError::kHz;
    p.alpha = 1e-4;
    return p;
  }
};

class FrameRateController {
 public:
  /// Throws surgsim::core::Error on target <= 0, alpha or beta <= 0, or an empty LOD range.
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
