// libFuzzer target: the Mitsuba 3 XML loader (pugixml, $parameters, ids and references,
// transforms, every plugin's parameter checks) on arbitrary text. File names resolve against an
// empty folder, so includes and meshes fail and only the XML is exercised. A voxcone::Error is
// the expected answer to a bad scene; anything else is a finding.

#include "voxcone/core/error.h"
#include "voxcone/scene/mitsuba.h"

#include <cstdint>
#include <cstdlib>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  try {
    const voxcone::Scene scene = voxcone::parseMitsubaScene(std::string(reinterpret_cast<const char*>(data), size),
                                                            "fuzz.xml", "/nonexistent-fuzz-dir", {{"spp", "4"}});
    for (const voxcone::UVec3& t : scene.triangles)
      if (t.x >= scene.positions.size() || t.y >= scene.positions.size() || t.z >= scene.positions.size()) std::abort();
    for (uint32_t m : scene.triMaterial)
      if (m >= scene.materials.size()) std::abort();
  } catch (const voxcone::Error&) {
  }
  return 0;
}
