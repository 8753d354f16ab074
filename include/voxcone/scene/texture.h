#pragma once
/// \file texture.h
/// An image texture of linear RGB texels (8-bit PNG and JPEG files decoded from sRGB by
/// readImage, EXR taken as it is), looked up bilinearly with repeat wrapping.
///
/// Texture coordinates: (0, 0) is the image's bottom-left corner and (1, 1) its top-right, as
/// OBJ's `vt`, PLY's `u v` and Mitsuba's meshes give them (a glTF loader flips v, its origin
/// being the top-left). Texel (i, j) of a w x h image (j = 0 the top row) has its centre at
/// u = (i + 0.5) / w, v = 1 - (j + 0.5) / h.
///
/// No mip-maps: a pixel's samples, spread over its footprint, average what it covers (a
/// texture much finer than the pixels needs more samples to converge than a filtered lookup).

#include "voxcone/core/math.h"

#include <string>
#include <vector>

namespace voxcone {

class Texture {
public:
  /// `texels` row-major, the top row first, width x height of them (both >= 1). Throws Error on
  /// a size mismatch or a non-finite or negative texel.
  Texture(int width, int height, std::vector<Vec3> texels);

  /// The bilinear interpolation of the four texels around (u, v), repeated outside [0, 1).
  Vec3 lookup(const Vec2& uv) const;
  /// The mean of the texels (the texture's mean over the unit square, exactly, under bilinear
  /// interpolation with repeat wrapping).
  const Vec3& mean() const { return m_mean; }
  /// Texel (i, j), j = 0 the top row.
  const Vec3& texel(int i, int j) const { return m_texels[size_t(j) * size_t(m_width) + size_t(i)]; }
  int width() const { return m_width; }
  int height() const { return m_height; }

  /// The file it was read from (loadTexture), for writers and sidecars; empty otherwise.
  std::string file;

private:
  int m_width = 0, m_height = 0;
  std::vector<Vec3> m_texels;
  Vec3 m_mean{0.0f};
};

/// Read an image file as a texture (readImage: EXR, PNG, JPEG). Throws Error (one line) when
/// it cannot be read.
Texture loadTexture(const std::string& path);

}  // namespace voxcone
