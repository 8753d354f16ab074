#pragma once
// What every scene loader (JSON, Mitsuba XML) shares: the float range checks, the last step of
// loading, and the geodesic sphere (private to src/scene).

#include "voxcone/scene/scene.h"

#include <string>
#include <vector>

namespace voxcone::detail {

/// The range voxcone renders correctly in float, measured on cornell-box scaled and moved (the
/// same image mean to 4 digits from 1e-6 to 5e6 times its size, and moved up to 180 times its
/// size from the origin): a scene is refused when its largest side lies outside
/// [kMinSceneExtent, kMaxSceneExtent] or a coordinate is more than kMaxSceneOffset sides from
/// the origin. Beyond them it was wrong, not slow: scaled 1e7 the image mean was 0.07 instead of
/// 0.12, 1e8 black; 1e-8 1.4% off; moved 1800 sides away 1.1% off, 18,000 sides -13%.
constexpr double kMinSceneExtent = 1e-4, kMaxSceneExtent = 1e9, kMaxSceneOffset = 256.0;
/// No coordinate (camera included) beyond this: the extent and offset bounds allow less anyway.
constexpr double kMaxSceneReach = 1e12;

/// Throws SceneError(file, "shapes", ...) when the finalized scene lies outside the range above.
void checkScenePrecision(const Scene& scene, const std::string& file);

/// The end of every loader: no triangles is an error; finalize(); the range check; no light is
/// an error.
void finishScene(Scene& scene, const std::string& file);

/// Append a shape: its vertices (per-vertex normals when `smooth` and `nrm` is not empty;
/// texture coordinates when `uvs` is not empty, one per vertex) and triangles (indices into
/// `pos`), with `triMat` one material for all or one per triangle.
void appendShape(Scene& scene, const std::string& name, const std::vector<Vec3>& pos, const std::vector<Vec3>& nrm,
                 const std::vector<Vec2>& uvs, const std::vector<UVec3>& tris, const std::vector<uint32_t>& triMat,
                 bool smooth);

/// The index in scene.textures of the image file `path` (read once per path). Throws Error.
int32_t textureIndex(Scene& scene, const std::string& path);

/// A geodesic sphere: an icosahedron subdivided `level` times (20 * 4^level triangles),
/// projected to the sphere of `radius` (scene units) about `center`; `inward` reverses the
/// winding. Appends to pos and tris (indices offset by pos' size).
void makeSphere(const Vec3& center, float radius, int level, bool inward, std::vector<Vec3>& pos,
                std::vector<UVec3>& tris);

}  // namespace voxcone::detail
