#include "render/render_scale.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"

namespace surgsim {

RenderScaleController::RenderScaleController(const RenderScaleParams& params) : params_(params) {
  if (!(params.min_scale >= 0.25 && params.min_scale <= 1.0)) {
    core::throw_error("render scale: min_scale ", params.min_scale, " is outside [0.25, 1]");
  }
  if (!(params.target_work_s > 0.0) || !std::isfinite(params.target_work_s)) {
    core::throw_error("render scale: target work ", params.target_work_s, " s must be positive");
  }
  if (!(params.gain > 0.0 && params.gain <= 1.0) || !(params.smoothing > 0.0 && params.smoothing <= 1.0)) {
    core::throw_error("render scale: gain ", params.gain, " and smoothing ", params.smoothing, " must be in (0, 1]");
  }
  if (!(params.deadband >= 0.0) || !std::isfinite(params.deadband)) {
    core::throw_error("render scale: deadband ", params.deadband, " must be 0 or more");
  }
  hold_ = std::log2(1.0 + params.deadband);
}

double RenderScaleController::update(double work_s) noexcept {
  if (!active() || !std::isfinite(work_s) || !(work_s > 0.0)) return scale_;
  ++frames_;
  const double e = std::log2(work_s / params_.target_work_s);
  error_ += params_.smoothing * (e - error_);
  if (std::abs(error_) > hold_) {
    scale_ = std::clamp(scale_ * std::exp2(-params_.gain * error_ / 2.0), params_.min_scale, 1.0);
  }
  if (scale_ < 1.0) ++frames_scaled_;
  min_seen_ = std::min(min_seen_, scale_);
  return scale_;
}

}  // namespace surgsim
