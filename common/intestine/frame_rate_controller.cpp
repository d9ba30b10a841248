#include "intestine/frame_rate_controller.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"

using namespace surgsim::core;

namespace surgsim::intestine {

FrameRateController::FrameRateController(const FrameRateParams& params) : params_(params) {
  if (!(params.target_hz > 0) || !(params.alpha > 0) || !(params.beta > 0) || params.lod_min < 0 ||
      params.lod_max < params.lod_min || !std::isfinite(params.target_hz)) {
    throw_error("frame rate controller: target_hz, alpha, beta must be > 0 and 0 <= lod_min <= lod_max (got target ",
                params.target_hz, " Hz, alpha ", params.alpha, ", beta ", params.beta, ", lod ", params.lod_min, "..",
                params.lod_max, ")");
  }
  reset();
}

void FrameRateController::reset() noexcept {
  const int lod0 = std::clamp(params_.initial_lod, params_.lod_min, params_.lod_max);
  eps_ = 0;
  n_ = params_.lod_max - lod0;
  rho_ = n_ + 0.5;  // in the middle of the level: no switch on the first small error
  lod_ = lod0;
}

int FrameRateController::update(double f) noexcept {
  if (!(f > 0) || !std::isfinite(f)) return lod_;
  const double e = params_.error == FrameRateError::kHz ? params_.target_hz - f : std::log2(params_.target_hz / f);
  const double eps_next = eps_ + params_.alpha * e;
  const double rho_max = std::nextafter(static_cast<double>(params_.lod_max - params_.lod_min + 1), 0.0);
  rho_ = std::clamp(rho_ + params_.beta * (eps_next - eps_), 0.0, rho_max);
  eps_ = eps_next;
  n_ = static_cast<int>(std::floor(rho_));
  lod_ = std::clamp(params_.lod_max - n_, params_.lod_min, params_.lod_max);
  return lod_;
}

int FrameRateController::update_from_frame_time(double seconds) noexcept {
  if (!(seconds > 0) || !std::isfinite(seconds)) return lod_;
  return update(1.0 / seconds);
}

}  // namespace surgsim::intestine
