// libFuzzer target: the OBJ loader (tinyobjloader and voxcone's checks) on arbitrary text; the
// input after the first NUL byte, if any, is the material library it may name. A MeshError is
// the expected answer to a malformed file; anything else is a finding.

#include "voxcone/core/error.h"
#include "voxcone/scene/mesh.h"

#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const char* text = reinterpret_cast<const char*>(data);
  const char* nul = static_cast<const char*>(std::memchr(text, 0, size));
  const std::string obj(text, nul ? size_t(nul - text) : size);
  const std::string mtl = nul ? std::string(nul + 1, size - size_t(nul - text) - 1) : std::string();
  try {
    const voxcone::TriangleMesh mesh = voxcone::parseObj(obj, mtl, "fuzz.obj");
    for (const voxcone::UVec3& t : mesh.triangles)
      if (t.x >= mesh.positions.size() || t.y >= mesh.positions.size() || t.z >= mesh.positions.size()) std::abort();
    if (!mesh.faceMaterial.empty() && mesh.faceMaterial.size() != mesh.triangles.size()) std::abort();
  } catch (const voxcone::Error&) {
  }
  return 0;
}
