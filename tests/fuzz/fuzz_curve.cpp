// Fuzz target: the quasi non-linear law's curve files (common/nonlinear/nonlinear_law.cpp, read_curve through its
// stream overload) and the fit a scene's law makes of each (fit_curve, degree 6 as the shipped scenes).
// Expected: surgsim::core::Error (see fuzz_support.h); anything else escaping is a finding.
#include <sstream>

#include "core/error.h"
#include "fuzz_support.h"
#include "nonlinear/nonlinear_law.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace surgsim;
  std::istringstream in{std::string(fuzz::as_text(data, size))};
  try {
    const nonlinear::Curve curve = nonlinear::read_curve(in, "curve.csv");
    (void)nonlinear::fit_curve(curve, 6);
  } catch (const core::Error&) {
  }
  return 0;
}
