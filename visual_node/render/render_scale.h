// Dynamic resolution for the visual node (Renderer::set_render_scale): when the frames' work does not fit the frame
// period, because the CPUs are shared with a browser, an encoder or the haptic node, the picture is drawn at a lower
// resolution and scaled back up, instead of frames being dropped.
//
// A frame's work is mostly the rasterizer's (llvmpipe: fragment shading), which falls with the number of pixels,
// i.e. with the square of the scale s. The controller is an integral law on the octaves of frame work, as the
// intestine's LOD controller (intestine/frame_rate_controller.h):
//
//   e_k     = log2(w_k / W0)                                  w_k the frame's work, W0 the target work
//   ebar_k  = ebar_{k-1} + lambda (e_k - ebar_{k-1})          smoothed, so that one slow frame does not act alone
//   s_{k+1} = clamp(s_k 2^(-gain ebar_k / 2), s_min, 1)       when |ebar_k| > log2(1 + deadband), else s_k
//
// With the work all pixels, gain 1 would close the whole gap in one frame; 0.25 closes a quarter a frame. The
// deadband keeps the scale still while the work is near its target (no flicker of resolution), and the target sits
// below the period (share of it, default 0.6) so that the frames that do overrun, a preemption or a slow encode,
// are caught up by the visual node's schedule. With s_min = 1 the controller is off: the scale stays 1.
// Run phase: update() is a few flops, no allocation.
#pragma once

namespace surgsim {

struct RenderScaleParams {
  double min_scale = 1.0;       // lowest scale, [0.25, 1]; 1 = off
  double target_work_s = 0.02;  // W0, s (the visual node: visual.rate_hz's period x 0.6)
  double deadband = 0.15;       // the scale holds while the smoothed work is within W0 x / (1 + deadband)
  double gain = 0.25;           // fraction of the gap (in octaves of work) closed a frame
  double smoothing = 0.5;       // lambda, weight of the newest frame in the smoothed error
};

class RenderScaleController {
 public:
  /// Throws surgsim::core::Error on min_scale outside [0.25, 1], a target, gain or smoothing not in (0, 1] (target >
  /// 0), or a negative deadband.
  explicit RenderScaleController(const RenderScaleParams& params);

  /// Feeds the work of the frame just drawn (s); returns the scale to draw the next one at. A non-finite or
  /// non-positive work is ignored.
  double update(double work_s) noexcept;

  double scale() const { return scale_; }
  bool active() const { return params_.min_scale < 1.0; }
  /// Frames fed, and those after which the scale was below 1.
  long frames() const { return frames_; }
  long frames_scaled() const { return frames_scaled_; }
  double min_seen() const { return min_seen_; }
  const RenderScaleParams& params() const { return params_; }

 private:
  RenderScaleParams params_;
  double scale_ = 1.0;
  double error_ = 0.0;  // ebar
  double hold_ = 0.0;   // log2(1 + deadband)
  long frames_ = 0;
  long frames_scaled_ = 0;
  double min_seen_ = 1.0;
};

}  // namespace surgsim
