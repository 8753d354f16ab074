#include "voxcone/core/sampler.h"

#include "voxcone/core/error.h"

namespace voxcone {

const std::vector<std::string>& samplerNames() {
  static const std::vector<std::string> names = {"sobol", "independent"};
  return names;
}

SamplerKind samplerKindFromName(const std::string& name) {
  const std::vector<std::string>& names = samplerNames();
  for (size_t i = 0; i < names.size(); ++i)
    if (names[i] == name) return SamplerKind(i);
  throw SettingsError("unknown sampler '" + name + "' (one of sobol, independent)");
}

}  // namespace voxcone
