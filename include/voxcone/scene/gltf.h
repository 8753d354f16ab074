#pragma once
/// \file gltf.h
/// glTF 2.0 scenes (.gltf with its buffers and images, or .glb) through tinygltf.
///
/// What is read: the default scene's node tree (matrix or TRS transforms); triangle primitives
/// (POSITION, NORMAL for smooth shading, TEXCOORD_0; indexed or not; a negative determinant flips
/// the winding); pbrMetallicRoughness materials: baseColorFactor x baseColorTexture, metallic 0
/// a coated diffuse (rough_plastic of KHR_materials_ior's index, alpha = roughness^2; a
/// Lambertian at roughness 1), metallic 1 a rough conductor tinted by the base colour (alpha = roughness^2,
/// a perfect reflector's Fresnel), KHR_materials_transmission (> 0) a dielectric of
/// KHR_materials_ior's index (rough when roughness > 0), emissiveFactor x
/// KHR_materials_emissive_strength as emitted radiance (both sides, as Blender's emission); the
/// first perspective camera in node order; KHR_lights_punctual point and directional lights,
/// converted as Blender's glTF importer converts them by default (W = lm / 683: a point light's
/// intensity I(cd) / 683 W/sr, a directional light's illuminance E(lx) / 683 W/m^2).
///
/// What voxcone cannot render as the file says is an error (spot lights, sparse accessors,
/// texture coordinates other than TEXCOORD_0 for the base colour, points and lines) or a one-line
/// warning naming what was dropped (metallic-roughness, normal, occlusion and emissive textures,
/// alpha blending and masks, skins and
/// morph targets, KHR_texture_transform); never silently different.
/// glTF's texture coordinates put v = 0 at an image's top row; voxcone's at the bottom (v flips).

#include "voxcone/scene/scene.h"

#include <string>
#include <vector>

namespace voxcone {

/// Whether `path` names a glTF file (.gltf or .glb, any case).
bool isGltfScenePath(const std::string& path);

/// A whole glTF scene: meshes, materials, its first perspective camera (required), its lights
/// (a scene without any light is an error, as every loader's). Warnings go to `warnings` (or
/// stderr when null). Throws SceneError with one line naming the file.
Scene loadGltfScene(const std::string& path, std::vector<std::string>* warnings = nullptr);

/// Append the meshes of a glTF file (with their materials; not its cameras and lights) to
/// `scene`, every node's transform followed by `xf`. For JSON's {"type": "gltf"} shapes.
/// Throws SceneError.
void appendGltfMeshes(Scene& scene, const std::string& path, const glm::mat4& xf, std::vector<std::string>& warnings);

}  // namespace voxcone
