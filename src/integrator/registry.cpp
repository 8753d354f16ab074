#include "voxcone/core/error.h"
#include "voxcone/integrator/integrator.h"
#include "voxcone/integrator/path.h"
#include "voxcone/integrator/photon_mapping.h"
#include "voxcone/integrator/voxel_cone/voxel_cone.h"
#include "voxcone/integrator/whitted.h"

#include <map>
#include <mutex>

namespace voxcone {

namespace {
std::mutex g_mutex;

/// The table of built-in integrators, filled on first use.
std::map<std::string, IntegratorFactory>& table() {
  static std::map<std::string, IntegratorFactory> t = {
      {"path", [](const IntegratorContext& c) { return std::unique_ptr<Integrator>(new PathIntegrator(c)); }},
      {"pm", [](const IntegratorContext& c) { return std::unique_ptr<Integrator>(new PhotonMappingIntegrator(c)); }},
      {"voxcone", [](const IntegratorContext& c) { return std::unique_ptr<Integrator>(new VoxelConeIntegrator(c)); }},
      {"whitted", [](const IntegratorContext& c) { return std::unique_ptr<Integrator>(new WhittedIntegrator(c)); }},
  };
  return t;
}
}  // namespace

void registerIntegrator(const std::string& name, IntegratorFactory factory) {
  std::lock_guard<std::mutex> lock(g_mutex);
  table()[name] = std::move(factory);
}

std::unique_ptr<Integrator> createIntegrator(const std::string& name, const IntegratorContext& context) {
  IntegratorFactory f;
  {
    std::lock_guard<std::mutex> lock(g_mutex);
    auto it = table().find(name);
    if (it == table().end()) {
      std::string known;
      for (const auto& kv : table()) known += (known.empty() ? "" : ", ") + kv.first;
      throw SettingsError("unknown method '" + name + "' (known: " + known + ")");
    }
    f = it->second;
  }
  return f(context);
}

std::vector<std::string> integratorNames() {
  std::lock_guard<std::mutex> lock(g_mutex);
  std::vector<std::string> names;
  for (const auto& kv : table()) names.push_back(kv.first);
  return names;
}

}  // namespace voxcone
