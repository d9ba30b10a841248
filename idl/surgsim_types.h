// The DDS types of the current wire version (idl/Surgsim.idl): surgsim::msg::X names surgsim::msg::v3::X, so code
// says msg::ContactFrame whatever the version. Include this, never the generated headers directly.
#pragma once
#include "Surgsim.h"
#include "SurgsimPubSubTypes.h"

namespace surgsim {
namespace msg {
using namespace v3;  // NOLINT(google-build-using-namespace): the wire version in use
}  // namespace msg
}  // namespace surgsim
