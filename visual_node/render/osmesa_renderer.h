// The OSMesa backend of Renderer (internal: use make_renderer("osmesa", ...)).
#pragma once
#include <memory>

#include "render/renderer.h"

namespace surgsim {

/// Off-screen GL 3.3 core-profile renderer (falls back to a compatibility context, named "osmesa-compat").
/// Owns its RGBA colour buffer and 24-bit depth buffer. Use from one thread at a time; several renderers may
/// coexist (each makes its context current when it starts a frame). Throws surgsim::core::Error when the context or the
/// shaders cannot be created, with the GL info log.
std::unique_ptr<Renderer> make_osmesa_renderer(int width, int height);

}  // namespace surgsim
