// libFuzzer target: the PLY loader on arbitrary bytes. A MeshError is the expected answer to a
// malformed file; anything else (a crash, a sanitizer report, another exception, a mesh whose
// indices point outside its vertices) is a finding.

#include "voxcone/core/error.h"
#include "voxcone/scene/mesh.h"

#include <cstdint>
#include <cstdlib>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  try {
    const voxcone::TriangleMesh mesh = voxcone::parsePly(std::string(reinterpret_cast<const char*>(data), size), "fuzz.ply");
    for (const voxcone::UVec3& t : mesh.triangles)
      if (t.x >= mesh.positions.size() || t.y >= mesh.positions.size() || t.z >= mesh.positions.size()) std::abort();
    if (!mesh.normals.empty() && mesh.normals.size() != mesh.positions.size()) std::abort();
  } catch (const voxcone::Error&) {
  }
  return 0;
}
