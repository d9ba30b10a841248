// Fuzz target: the organ-curve cache (common/nonlinear/organ_curves.cpp, load_organ_curves). The expected key is
// the one the input's key line carries (when it has one), so that inputs reach the rows.
// Expected: none. load_organ_curves reports a missing, foreign or damaged file by returning false and never throws,
// so any exception escaping is a finding (see fuzz_support.h).
#include <cinttypes>
#include <cstdio>
#include <string>

#include "fuzz_support.h"
#include "nonlinear/organ_curves.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace surgsim;
  const std::string text(fuzz::as_text(data, size));
  std::uint64_t key = 0;
  const std::size_t at = text.find("key=");
  if (at != std::string::npos) std::sscanf(text.c_str() + at, "key=%" SCNx64, &key);
  const std::string path = fuzz::write_input("organ-curves.csv", text);
  nonlinear::OrganCurves curves;
  std::string why;
  (void)nonlinear::load_organ_curves(path, key, curves, &why);
  return 0;
}
