#pragma once
/// \file triangle.h
/// Watertight ray-triangle intersection (Woop, Benthin & Wald 2013, "Watertight Ray/Triangle
/// Intersection", JCGT 2(1)): rays through shared edges and vertices hit exactly one of the
/// triangles, never fall through a crack.

#include "voxcone/core/bounds.h"
#include "voxcone/core/ray.h"

#include <cstdint>
#include <limits>
#include <vector>

namespace voxcone {

/// Four triangles side by side for the 4-wide (SSE) watertight test of the HBVH's and the
/// kd-tree's leaves; unused lanes hold NaN vertices (never hit).
struct alignas(16) Triangle4 {
  /// Left uninitialized, also by std::vector::resize: the HBVH sizes its packet array first
  /// and fills it in parallel (zeroing 30 MB for the dragon first cost 15 ms).
  Triangle4() {}
  float v[3][3][4];  ///< [vertex][axis][lane]
  uint32_t id[4];    ///< original triangle index per lane
};

/// The bounds of triangle t, or false when an index is out of range or a vertex is not finite
/// (such triangles are left out of every structure).
inline bool triangleBounds(const std::vector<Vec3>& pos, const UVec3& t, Bounds3& out) {
  if (t.x >= pos.size() || t.y >= pos.size() || t.z >= pos.size()) return false;
  out = Bounds3();
  out.extend(pos[t.x]);
  out.extend(pos[t.y]);
  out.extend(pos[t.z]);
  return isFinite(out.lo) && isFinite(out.hi);
}

/// Write the triangles ids[0..count) to out[0 .. (count + 3) / 4), four to a packet (NaN
/// vertices fill the unused lanes).
inline void packTriangles(const std::vector<Vec3>& pos, const std::vector<UVec3>& tris, const uint32_t* ids,
                          uint32_t count, Triangle4* out) {
  for (uint32_t first = 0; first < count; first += 4) {
    Triangle4& t4 = *out++;
    for (uint32_t lane = 0; lane < 4; ++lane) {
      const bool used = first + lane < count;
      t4.id[lane] = used ? ids[first + lane] : 0u;
      for (int vtx = 0; vtx < 3; ++vtx) {
        const Vec3 v = used ? pos[tris[ids[first + lane]][vtx]] : Vec3(std::numeric_limits<float>::quiet_NaN());
        for (int a = 0; a < 3; ++a) t4.v[vtx][a][lane] = v[a];
      }
    }
  }
}

/// Append the triangles ids[0..count) to `out`, four to a packet.
inline void packTriangles(const std::vector<Vec3>& pos, const std::vector<UVec3>& tris, const uint32_t* ids,
                          uint32_t count, std::vector<Triangle4>& out) {
  const size_t at = out.size();
  out.resize(at + (count + 3u) / 4u);
  packTriangles(pos, tris, ids, count, out.data() + at);
}

/// Per-ray constants of the watertight test: the axis permutation and shear.
struct WatertightRay {
  int kx, ky, kz;
  float sx, sy, sz;
  float dz;  ///< |dir[kz]|: the error bound's scale (watertightDistanceError)
  explicit WatertightRay(const Vec3& dir) {
    // kz: dimension where the direction is largest in magnitude; swap kx,ky to keep winding.
    const Vec3 a = glm::abs(dir);
    kz = maxDimension(a);
    kx = kz == 2 ? 0 : kz + 1;
    ky = kx == 2 ? 0 : kx + 1;
    if (dir[kz] < 0.0f) std::swap(kx, ky);
    // One division: the shear by the reciprocal (consistent for every triangle, which is all
    // watertightness needs).
    sz = 1.0f / dir[kz];
    sx = dir[kx] * sz;
    sy = dir[ky] * sz;
    dz = std::fabs(dir[kz]);
  }
};

/// A bound on the rounding error of the watertight test's distance, from the sheared vertices
/// (x, y per vertex), their unscaled z (the origin-relative coordinate along kz), the edge
/// functions e = (u, v, w) and 1/det (the error analysis of PBRT 4th ed., section 6.8.4, eqs.
/// 6.31-6.38), for the ray scaled to |dir[kz]| = 1: compare it with t |dir[kz]|. A computed t at
/// or below it may be a hit behind the origin: the own surface of a spawned ray. It grows with
/// the triangle's extent as seen from the origin, which is why no offset of the origin alone
/// can prevent re-hits. (PBRT's terms mix the sheared x, y with z scaled by 1/dir[kz], which
/// bounds the error only for directions of about unit length: for a 1.1 cm segment given as an
/// unnormalized direction the bound came out at t = 0.35, and a wall 3 mm from the origin, hit
/// at t = 0.29, was not seen; tests/accel, Accel.ShortSegmentsSeeAWallNearTheirStart.)
inline float watertightDistanceError(float ax, float ay, float az, float bx, float by, float bz, float cx, float cy,
                                     float cz, float u, float v, float w, float invDet) {
  const float maxZ = std::max(std::fabs(az), std::max(std::fabs(bz), std::fabs(cz)));
  const float maxX = std::max(std::fabs(ax), std::max(std::fabs(bx), std::fabs(cx)));
  const float maxY = std::max(std::fabs(ay), std::max(std::fabs(by), std::fabs(cy)));
  const float maxE = std::max(std::fabs(u), std::max(std::fabs(v), std::fabs(w)));
  const float deltaZ = errorGamma(3) * maxZ;
  const float deltaX = errorGamma(5) * (maxX + maxZ);
  const float deltaY = errorGamma(5) * (maxY + maxZ);
  const float deltaE = 2.0f * (errorGamma(2) * (maxX * maxY) + deltaY * maxX + deltaX * maxY);
  return 3.0f * (errorGamma(3) * (maxE * maxZ) + deltaE * maxZ + deltaZ * maxE) * std::fabs(invDet);
}

/// The watertight tests compare the scaled distance with tMax times this before they divide, and
/// the divided distance t with tMax itself: t < tMax, whatever rounding the products make (t is
/// within 4 ulps of the scaled distance over det; this loosens by 16), so that which of two hits
/// at the same t a traversal keeps can be made independent of its order (Hbvh).
constexpr float kTMaxPrefilter = 1.0f + 0x1p-20f;

/// Test ray (origin, wr) against triangle (p0, p1, p2) for t in (tMin, tMax). On a hit writes t
/// and barycentrics (b1, b2) of p1 and p2 and returns true. Both sides hit. A hit counts only
/// where its t exceeds its own error bound (watertightDistanceError) as well as tMin.
inline bool intersectTriangleWatertight(const Vec3& origin, const WatertightRay& wr, const Vec3& p0,
                                        const Vec3& p1, const Vec3& p2, float tMin, float tMax, float& tOut,
                                        float& b1Out, float& b2Out) {
  // Vertices relative to the origin, permuted and sheared so the ray is +z through (0,0).
  const Vec3 A = p0 - origin, B = p1 - origin, C = p2 - origin;
  const float ax = A[wr.kx] - wr.sx * A[wr.kz], ay = A[wr.ky] - wr.sy * A[wr.kz];
  const float bx = B[wr.kx] - wr.sx * B[wr.kz], by = B[wr.ky] - wr.sy * B[wr.kz];
  const float cx = C[wr.kx] - wr.sx * C[wr.kz], cy = C[wr.ky] - wr.sy * C[wr.kz];
  // Scaled barycentrics: 2D edge functions.
  float u = cx * by - cy * bx;
  float v = ax * cy - ay * cx;
  float w = bx * ay - by * ax;
  // Exactly zero: recompute in double so that edges are decided consistently (the paper's
  // fallback for watertightness).
  if (u == 0.0f || v == 0.0f || w == 0.0f) {
    u = static_cast<float>(double(cx) * double(by) - double(cy) * double(bx));
    v = static_cast<float>(double(ax) * double(cy) - double(ay) * double(cx));
    w = static_cast<float>(double(bx) * double(ay) - double(by) * double(ax));
  }
  if ((u < 0.0f || v < 0.0f || w < 0.0f) && (u > 0.0f || v > 0.0f || w > 0.0f)) return false;
  const float det = u + v + w;
  if (det == 0.0f) return false;
  // Scaled hit distance, compared against the range before dividing (tMax loosened: the divided
  // distance decides, below).
  const float az = wr.sz * A[wr.kz], bz = wr.sz * B[wr.kz], cz = wr.sz * C[wr.kz];
  const float tScaled = u * az + v * bz + w * cz;
  const float tMaxLoose = tMax * kTMaxPrefilter;
  if (det < 0.0f ? (tScaled >= tMin * det || tScaled < tMaxLoose * det)
                 : (tScaled <= tMin * det || tScaled > tMaxLoose * det))
    return false;
  const float invDet = 1.0f / det;
  const float t = tScaled * invDet;
  if (!(t < tMax)) return false;
  if (!(t * wr.dz > watertightDistanceError(ax, ay, A[wr.kz], bx, by, B[wr.kz], cx, cy, C[wr.kz], u, v, w, invDet)))
    return false;
  tOut = t;
  b1Out = v * invDet;
  b2Out = w * invDet;
  return true;
}

}  // namespace voxcone
