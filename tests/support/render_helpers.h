#pragma once
// Rendering a scene with an integrator by name, for the integrator tests.

#include "voxcone/accel/hbvh.h"
#include "voxcone/integrator/integrator.h"

#include <nlohmann/json.hpp>

#include <string>

namespace voxcone::test {

/// Build the HBVH, create `method` with `options`, prepare it and render `settings`.
inline RenderResult renderWith(const Scene& scene, const std::string& method, RenderSettings settings,
                               nlohmann::json options = nlohmann::json::object()) {
  const Hbvh accel(scene);
  settings.method = method;
  IntegratorContext ctx{scene, accel, settings, options};
  auto integrator = createIntegrator(method, ctx);
  integrator->prepare(nullptr);
  return renderImage(scene, *integrator, settings);
}

}  // namespace voxcone::test
