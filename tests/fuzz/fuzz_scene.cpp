// libFuzzer target: the scene JSON loader (every key, range and reference check, the camera,
// shapes and lights it builds) on arbitrary text. Mesh files resolve against an empty folder,
// so only the JSON is exercised. A SettingsError or MeshError (both voxcone::Error) is the
// expected answer to a bad scene; anything else is a finding.

#include "voxcone/core/error.h"
#include "voxcone/scene/scene.h"

#include <cstdint>
#include <cstdlib>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  try {
    const voxcone::Scene scene =
        voxcone::parseScene(std::string(reinterpret_cast<const char*>(data), size), "fuzz.json", "/nonexistent-fuzz-dir");
    for (const voxcone::UVec3& t : scene.triangles)
      if (t.x >= scene.positions.size() || t.y >= scene.positions.size() || t.z >= scene.positions.size()) std::abort();
    for (uint32_t m : scene.triMaterial)
      if (m >= scene.materials.size()) std::abort();
  } catch (const voxcone::Error&) {
  }
  return 0;
}
