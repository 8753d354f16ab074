#pragma once
/// \file mitsuba.h
/// Mitsuba 3 XML scenes: the loader (what maps onto voxcone's Scene, with Mitsuba's conventions:
/// one-sided BSDFs, its camera frame and field-of-view axes, its max_depth), and the writers
/// that convert between Mitsuba XML and voxcone JSON (`voxcone convert`). docs/scenes.md "Mitsuba 3
/// scenes" lists the plugins and parameters; anything else is a SceneError naming the element,
/// the file and the line.

#include "voxcone/scene/scene.h"

#include <map>
#include <string>

namespace voxcone {

/// `-D name=value` parameters: they set `$name` in the scene, overriding `<default>` values.
using SceneParameters = std::map<std::string, std::string>;

/// True when `path` names a Mitsuba scene (ends in .xml, any case).
bool isMitsubaScenePath(const std::string& path);

/// Load a Mitsuba 3 XML scene. Relative file names (meshes, includes) are resolved against the
/// folder of the file that names them. Throws SceneError "FILE: line N: <element>: what".
Scene loadMitsubaScene(const std::string& path, const SceneParameters& parameters = {});

/// loadMitsubaScene on XML text; `origin` names it in errors, `baseDir` resolves file names.
Scene parseMitsubaScene(const std::string& xmlText, const std::string& origin, const std::string& baseDir,
                        const SceneParameters& parameters = {});

/// The tessellation of Mitsuba's analytic shapes (voxcone renders triangles only): a `sphere` becomes a geodesic sphere of
/// this level (20 * 4^5 = 20480 triangles, vertex normals radial), a `disk` a fan of this many
/// triangles (area 0.01% below the circle's).
constexpr int kMitsubaSphereLevel = 5;
constexpr int kMitsubaDiskSegments = 256;

/// Write `scene` as Mitsuba 3 XML at `xmlPath`; each shape's triangles (one file per run of
/// triangles with one material) go to binary little-endian PLY files in `<stem>_meshes/`
/// beside it, so positions survive bit for bit. Throws SceneError naming what has no Mitsuba
/// equivalent (Oren-Nayar, two-sided emission, method options Mitsuba lacks).
void writeMitsubaScene(const Scene& scene, const std::string& xmlPath);

/// Write `scene` as voxcone JSON at `jsonPath`, its shapes as PLY files in `<stem>_meshes/`.
void writeJsonScene(const Scene& scene, const std::string& jsonPath);

}  // namespace voxcone
