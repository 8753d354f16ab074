/// \file scene_hash.cpp
/// The hash a field keeps of the scene it was built for (VoxelField::checkScene).

#include "field_common.h"

#include "voxcone/scene/scene.h"

namespace voxcone {

/// A hash (FNV-1a on words) of what a field's content depends on: geometry (positions, smooth normals,
/// triangles, their materials), the materials' optical values and the point lights; not the
/// camera or the render settings, so one field serves many views.
uint64_t voxel::fieldSceneHash(const Scene& scene) {
  // FNV-1a's step on 8-byte words (a byte at a time was 19 ms on the dragon), the tail by bytes.
  uint64_t h = 1469598103934665603ull;
  auto bytes = [&](const void* data, size_t n) {
    const unsigned char* p = static_cast<const unsigned char*>(data);
    size_t i = 0;
    for (; i + 8 <= n; i += 8) {
      uint64_t w;
      std::memcpy(&w, p + i, 8);
      h = (h ^ w) * 1099511628211ull;
    }
    for (; i < n; ++i) h = (h ^ p[i]) * 1099511628211ull;
  };
  auto floats = [&](std::initializer_list<float> values) {
    for (float v : values) bytes(&v, sizeof v);
  };
  bytes(scene.positions.data(), scene.positions.size() * sizeof(Vec3));
  bytes(scene.normals.data(), scene.normals.size() * sizeof(Vec3));
  bytes(scene.triangles.data(), scene.triangles.size() * sizeof(UVec3));
  bytes(scene.triMaterial.data(), scene.triMaterial.size() * sizeof(uint32_t));
  for (const Material& m : scene.materials) {
    // twoSided too: a one-sided surface stores no photons on its back.
    const int32_t kinds[5] = {int32_t(m.type), int32_t(m.distribution), int32_t(m.twoSidedEmission), int32_t(m.twoSided),
                              m.albedoTexture};
    bytes(kinds, sizeof kinds);
    floats({m.albedo.x, m.albedo.y, m.albedo.z, m.sigmaRad, m.specular.x, m.specular.y, m.specular.z, m.ior, m.eta.x,
            m.eta.y, m.eta.z, m.k.x, m.k.y, m.k.z, m.roughness, m.emission.x, m.emission.y, m.emission.z});
  }
  bytes(scene.uvs.data(), scene.uvs.size() * sizeof(Vec2));
  for (const auto& t : scene.textures) {
    floats({float(t->width()), float(t->height())});
    for (int j = 0; j < t->height(); ++j) bytes(&t->texel(0, j), size_t(t->width()) * sizeof(Vec3));
  }
  for (const PointLight& l : scene.pointLights)
    floats({l.position.x, l.position.y, l.position.z, l.intensity.x, l.intensity.y, l.intensity.z});
  for (const DirectionalLight& l : scene.directionalLights)
    floats({l.direction.x, l.direction.y, l.direction.z, l.irradiance.x, l.irradiance.y, l.irradiance.z, l.halfAngle});
  if (const auto& env = scene.environment) {
    const Vec3 c = env->constantRadiance();
    const glm::mat3& m = env->toWorld();
    floats({c.x, c.y, c.z, env->scale(), float(env->width()), float(env->height()), m[0].x, m[0].y, m[0].z, m[1].x,
            m[1].y, m[1].z, m[2].x, m[2].y, m[2].z});
    bytes(env->texels().data(), env->texels().size() * sizeof(Vec3));
  }
  return h;
}

}  // namespace voxcone
