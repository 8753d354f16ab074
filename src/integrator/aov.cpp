// The AOV layers' names, channels and checks (integrator.h Aov).

#include "voxcone/core/error.h"
#include "voxcone/integrator/integrator.h"

#include <algorithm>

namespace voxcone {

const std::vector<std::string>& aovNames() {
  static const std::vector<std::string> names = {"albedo", "normal", "depth", "emitted", "direct", "indirect", "caustic"};
  return names;
}

std::vector<Aov> parseAovs(const std::string& list) {
  std::vector<Aov> out;
  size_t start = 0;
  while (start <= list.size()) {
    const size_t end = std::min(list.find(',', start), list.size());
    const std::string name = list.substr(start, end - start);
    const auto& names = aovNames();
    const auto it = std::find(names.begin(), names.end(), name);
    if (it == names.end()) {
      std::string known;
      for (const std::string& n : names) known += (known.empty() ? "" : ", ") + n;
      throw SettingsError("--aov: unknown layer '" + name + "' (known: " + known + ")");
    }
    const Aov a = Aov(it - names.begin());
    if (std::find(out.begin(), out.end(), a) != out.end()) throw SettingsError("--aov: " + name + " given twice");
    out.push_back(a);
    start = end + 1;
  }
  return out;
}

std::vector<std::string> aovChannels(Aov aov) {
  const auto rgb = [](const std::string& layer) {
    return std::vector<std::string>{layer + ".R", layer + ".G", layer + ".B"};
  };
  switch (aov) {
    case Aov::Albedo: return rgb("Albedo");
    case Aov::Normal: return {"Ns.X", "Ns.Y", "Ns.Z"};
    case Aov::Depth: return {"Z"};
    case Aov::Emitted: return rgb("Emitted");
    case Aov::Direct: return rgb("Direct");
    case Aov::Indirect: return rgb("Indirect");
    case Aov::Caustic: return rgb("Caustic");
  }
  return {};
}

bool isTermAov(Aov aov) { return aov != Aov::Albedo && aov != Aov::Normal && aov != Aov::Depth; }

void checkAovs(const Integrator& integrator, const std::vector<Aov>& layers) {
  if (integrator.separatesTerms()) return;
  for (Aov a : layers)
    if (isTermAov(a))
      throw SettingsError("--aov " + aovNames()[size_t(a)] + ": method " + integrator.name() +
                          " does not separate its terms (path, whitted and voxcone do)");
}

}  // namespace voxcone
