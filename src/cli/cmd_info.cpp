// `voxcone info SCENE`: mesh and HBVH statistics.

#include "cli_util.h"
#include "commands.h"
#include "voxcone/accel/hbvh.h"
#include "voxcone/core/parallel.h"
#include "voxcone/core/timer.h"
#include "voxcone/scene/scene.h"

#include <nlohmann/json.hpp>

namespace voxcone {

void addInfoCommand(CLI::App& app) {
  struct Opts {
    std::string scene;
    std::vector<std::string> defines;
    bool json = false;
    int threads = 0;
  };
  auto o = std::make_shared<Opts>();
  CLI::App* cmd = app.add_subcommand("info", "Print scene, mesh and HBVH statistics");
  cmd->add_option("scene", o->scene, "Scene file (JSON, Mitsuba 3 XML: .xml, or glTF 2.0: .gltf, .glb)")->required()->default_str("");
  addDefineOption(*cmd, o->defines);
  cmd->add_flag("--json", o->json, "Print JSON instead of a table");
  cmd->add_option("-t,--threads", o->threads, "Threads for the HBVH build (0 = all)")->check(CLI::Range(0, 4096));
  cmd->callback([o] {
    ThreadLimit limit(o->threads);
    Timer t;
    const Scene scene = loadScene(o->scene, parseDefines(o->defines));
    const double loadSec = t.seconds();
    const Hbvh accel(scene);
    nlohmann::json j;
    j["scene"] = scene.statsJson();
    j["scene"]["load_seconds"] = loadSec;
    j["hbvh"] = accel.statsJson();
    nlohmann::json shapes = nlohmann::json::array();
    for (const ShapeInfo& s : scene.shapes)
      shapes.push_back({{"name", s.name}, {"triangles", s.triangleCount}, {"smooth_normals", s.smoothNormals},
                        {"material", scene.materials[scene.triMaterial[s.firstTriangle]].name}});
    j["shapes"] = shapes;
    if (o->json) {
      std::printf("%s\n", j.dump(2).c_str());
      return;
    }
    const HbvhStats& h = accel.stats();
    std::printf("scene       %s\n", o->scene.c_str());
    std::printf("triangles   %zu  vertices %zu  shapes %zu  materials %zu  lights %zu\n", scene.triangleCount(),
                scene.positions.size(), scene.shapes.size(), scene.materials.size(), scene.lightCount());
    const Bounds3& b = scene.bounds();
    std::printf("bounds      [%g %g %g] - [%g %g %g]\n", b.lo.x, b.lo.y, b.lo.z, b.hi.x, b.hi.y, b.hi.z);
    for (const ShapeInfo& s : scene.shapes)
      std::printf("  shape %-20s %9u triangles  %s%s\n", s.name.c_str(), s.triangleCount,
                  scene.materials[scene.triMaterial[s.firstTriangle]].name.c_str(), s.smoothNormals ? "  smooth" : "");
    std::printf("hbvh        nodes %llu (quantized %llu)  leaves %llu  spheres %llu  depth %d  SAH %.2f  leaf %.2f tris  %.2f MiB  build %.3f s  kernels %s\n",
                (unsigned long long)h.nodes, (unsigned long long)h.quantizedNodes, (unsigned long long)h.leaves,
                (unsigned long long)h.sphereNodes,
                h.maxDepth, h.sahCost, h.avgLeafSize, double(h.bytes) / (1024.0 * 1024.0), h.buildSeconds,
                Hbvh::simdName(accel.simd()));
  });
}

}  // namespace voxcone
