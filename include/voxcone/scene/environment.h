#pragma once
/// \file environment.h
/// An environment light: radiance arriving from every direction at infinity, constant or from
/// an equirectangular (latitude-longitude) linear HDR image, importance-sampled by its
/// luminance times each row's solid angle (a 2D piecewise-constant distribution, pbrt-v4's
/// ImageInfiniteLight).
///
/// The map's frame: +y up; for a direction d (unit, from the scene towards the sky) in it,
///   u = 0.5 + atan2(d.z, d.x) / (2 pi)     (u = 0.5 towards +x, 0.75 towards +z, 0.25 towards -z)
///   v = acos(d.y) / pi = 0.5 - elevation / pi   (v = 0: the top row, the zenith)
/// which is Blender's mapping of an equirectangular world image once its Z-up axes are turned to
/// Y-up as glTF's importer turns them (Blender's (x, y, z) = this frame's (x, -z, y)). The
/// map's frame is turned into the world by `toWorld` (a rotation: rotate_deg about +y, or a
/// Mitsuba envmap's to_world). Texels are boxes (nearest lookup), the density the sampler draws.

#include "voxcone/core/math.h"

#include <memory>
#include <string>
#include <vector>

namespace voxcone {

class Environment {
public:
  /// The same radiance (W / (sr m^2) per channel) from every direction; sampled uniformly over
  /// the sphere.
  static Environment constant(const Vec3& radiance);
  /// An equirectangular map of width x height texels (row-major, the top row first), each
  /// multiplied by `scale`; `toWorld` turns the map's frame into the world (a rotation).
  /// Throws SettingsError for an empty map, a negative or non-finite texel or scale.
  static Environment image(int width, int height, std::vector<Vec3> texels, float scale, const glm::mat3& toWorld);

  bool isConstant() const { return m_width == 0; }
  /// Radiance arriving from direction `dir` (unit, pointing from the scene towards the sky).
  Vec3 radiance(const Vec3& dir) const;
  /// A direction drawn from u in [0,1)^2 with its solid-angle density in `pdf` (0: none drawn).
  Vec3 sample(const Vec2& u, float& pdf) const;
  /// The solid-angle density sample() draws `dir` with.
  float pdf(const Vec3& dir) const;
  /// The integral of radiance over the sphere, per channel (W / m^2): the flux through a disc of
  /// radius R facing all directions is pi R^2 times it.
  const Vec3& integral() const { return m_integral; }

  // What the scene writers and the hash need.
  const glm::mat3& toWorld() const { return m_toWorld; }
  float scale() const { return m_scale; }
  const Vec3& constantRadiance() const { return m_constant; }
  int width() const { return m_width; }
  int height() const { return m_height; }
  /// The texels as given (before `scale`).
  const std::vector<Vec3>& texels() const { return m_texels; }
  /// The file the map came from (for the writers; empty for a constant or a generated map).
  std::string file;

  /// The direction in the map's frame of (u, v) in [0,1]^2, and back (the mapping above).
  static Vec3 directionOf(float u, float v);
  static Vec2 uvOf(const Vec3& localDir);

private:
  Vec3 m_constant{0.0f};
  int m_width = 0, m_height = 0;
  std::vector<Vec3> m_texels;
  float m_scale = 1.0f;
  glm::mat3 m_toWorld{1.0f}, m_toLocal{1.0f};
  /// Per row: the conditional CDF over its columns (width + 1 entries, from 0 to 1) and its
  /// weight; the marginal CDF over rows (height + 1 entries).
  std::vector<float> m_rowCdf, m_marginalCdf, m_rowWeight;
  double m_totalWeight = 0.0;
  Vec3 m_integral{0.0f};
};

/// An equirectangular map read from an OpenEXR, PNG or JPEG file (readImage: EXR linear, 8-bit
/// files decoded from sRGB). Throws ImageError or SettingsError with a one-line message.
Environment loadEnvironmentMap(const std::string& path, float scale, const glm::mat3& toWorld);

/// The rotation by `degrees` about +y (right-handed: +x turns towards -z).
glm::mat3 rotationY(float degrees);
/// Whether m is a rotation: orthonormal columns within 1e-3, determinant positive.
bool isRotation(const glm::mat3& m);

}  // namespace voxcone
