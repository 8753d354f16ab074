/// \file voxel_field.cpp
/// The sparse voxel field: per level, one OpenVDB topology tree whose active values index a
/// brick table, and per-voxel attributes stored compactly as structure-of-arrays. This is the
/// only translation unit of the library that includes OpenVDB (its headers are slow to compile).
///
/// Layout of one level (why not OpenVDB value grids or a uint32 index per voxel in 4^3 leaves):
/// a flat wall leaves most of a dense leaf empty, so a dense index leaf costs ~19 bytes per active
/// voxel on the Cornell walls, more than all the attributes together. Instead voxels are grouped
/// in 4^3 bricks: the OpenVDB tree (Tree4<uint32_t, 4, 3, 2>, i.e. 4^3 leaves of bricks = 16^3
/// voxels; internal nodes of 8^3 and 16^3 children, whose tables cost 4 and 32 KB where the
/// default 16^3/32^3 cost 32 and 256 KB, which dominated the small coarse levels) maps a brick
/// coordinate to a brick index; the brick holds a 64-bit occupancy mask and
/// the index of its first voxel, and voxel (i, j, k) is
///   brickBase[b] + popcount(brickMask[b] & ((1 << bit) - 1)),  bit = (i&3)<<4 | (j&3)<<2 | (k&3)
/// (the NanoVDB "index grid" idea). That is ~2 bytes of topology per voxel on a wall.
///
/// Attributes per voxel (compact encodings, decoded by the accessors below):
///   coverage  half    finest level: surface area in the voxel / voxelSize^2 (may exceed 1);
///                     coarser levels: opacity (mean child opacity). Opacity = min(1, coverage).
///   normal    uint16  octahedral unit vector, 2 x 8 bit (Cigolle et al. 2014, "A Survey of
///                     Efficient Representations for Independent Unit Vectors"; < 1 degree
///                     error), stored renormalized (the opacity-weighted sum's length is not kept)
///   albedo    3 x uint8 linear [0, 1]
///   radiance  2 x uint32 front and back side, RGB9E5 shared exponent (EXT_texture_shared_exponent):
///                     9-bit mantissas, relative error <= 2^-10 on the largest channel, range
///                     [0, 65408] W/(sr m^2)
///   axes      3 x uint8 mips only: opacity-weighted mean |normal| per axis
/// 15 bytes per voxel at the finest level (15 in the mips: axes instead of albedo) plus ~2
/// bytes of topology. With one radiance per voxel (sides mixed) cornell-dragon level 10 (5.9 M
/// voxels, 7.9 M with the mips) took 92.8 MiB; 2x16-bit normals and 3 x half radiance (15
/// bytes) took 135 MB; albedo in every mip and 32^3 root children 101.3 MiB.

#include "voxcone/voxel/voxel_field.h"

#include "voxelize.h"

#include "voxcone/core/error.h"
#include "voxcone/core/timer.h"
#include "voxcone/image/image_io.h"
#include "voxcone/photon/photon_tracer.h"
#include "voxcone/scene/scene.h"

#include <array>
#include <Imath/half.h>
#include <nlohmann/json.hpp>
#include <openvdb/openvdb.h>
#include <openvdb/io/File.h>
#include <openvdb/tree/Tree.h>
#include <openvdb/tree/ValueAccessor.h>

#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <cstring>
#include <cmath>
#include <mutex>

namespace voxcone {

namespace {

using voxel::VoxelArrays;
using Half = Imath::half;
/// Brick coordinate -> brick index. Only active values are meaningful.
using IndexTree = openvdb::tree::Tree4<uint32_t, 4, 3, 2>::Type;
/// A read-only accessor that does not register with the tree (cheap to make per query).
using IndexAccessor = openvdb::tree::ValueAccessor<const IndexTree, false>;

// ---- compact encodings ----

/// Octahedral encoding of a unit vector in 2 x 8 bits.
uint16_t encodeNormal(const Vec3& n) {
  const float l1 = std::abs(n.x) + std::abs(n.y) + std::abs(n.z);
  if (!(l1 > 0.0f)) return encodeNormal(Vec3(0.0f, 0.0f, 1.0f));
  float x = n.x / l1, y = n.y / l1;
  if (n.z < 0.0f) {
    const float ox = (1.0f - std::abs(y)) * (x >= 0.0f ? 1.0f : -1.0f);
    const float oy = (1.0f - std::abs(x)) * (y >= 0.0f ? 1.0f : -1.0f);
    x = ox;
    y = oy;
  }
  auto q = [](float v) { return uint16_t(std::lround((std::clamp(v, -1.0f, 1.0f) * 0.5f + 0.5f) * 254.0f)); };
  return uint16_t(q(x) | (q(y) << 8));
}
/// The octahedral decode before normalization: the direction, not unit length.
Vec3 decodeNormalDirection(uint16_t code) {
  const float x = float(code & 0xffu) / 254.0f * 2.0f - 1.0f;
  const float y = float(code >> 8) / 254.0f * 2.0f - 1.0f;
  Vec3 n(x, y, 1.0f - std::abs(x) - std::abs(y));
  const float t = std::max(-n.z, 0.0f);
  n.x += n.x >= 0.0f ? -t : t;
  n.y += n.y >= 0.0f ? -t : t;
  return n;
}
Vec3 decodeNormal(uint16_t code) { return glm::normalize(decodeNormalDirection(code)); }
uint8_t encodeUnorm8(float v) { return uint8_t(std::lround(std::clamp(v, 0.0f, 1.0f) * 255.0f)); }
/// RGB9E5 (OpenGL EXT_texture_shared_exponent): three 9-bit mantissas, one 5-bit exponent.
/// Values saturate at 65408 instead of overflowing; negatives clamp to 0.
uint32_t encodeRgb9e5(const Vec3& rgb) {
  constexpr float kMax = 65408.0f;  // (2^9 - 1) / 2^9 * 2^(31 - 15)
  const float r = std::clamp(rgb.x, 0.0f, kMax), g = std::clamp(rgb.y, 0.0f, kMax), b = std::clamp(rgb.z, 0.0f, kMax);
  const float maxc = std::max(r, std::max(g, b));
  if (!(maxc > 0.0f)) return 0;
  int e2 = 0;
  std::frexp(maxc, &e2);                             // maxc = f * 2^e2, f in [0.5, 1)
  int exp = std::max(-16, e2 - 1) + 1 + 15;          // shared biased exponent
  if (std::floor(maxc / std::ldexp(1.0f, exp - 15 - 9) + 0.5f) >= 512.0f) ++exp;
  const float scale = std::ldexp(1.0f, exp - 15 - 9);
  auto m = [&](float v) { return std::min(511u, uint32_t(std::floor(v / scale + 0.5f))); };
  return m(r) | (m(g) << 9) | (m(b) << 18) | (uint32_t(exp) << 27);
}
Vec3 decodeRgb9e5(uint32_t code) {
  // 2^(exponent - 15 - 9) built from its bits: biased exponent field (code >> 27) - 24 + 127,
  // always in [103, 134], a normal float (std::ldexp was a tenth of the cone lookups' time).
  const uint32_t bits = ((code >> 27) + 103u) << 23;
  float scale;
  std::memcpy(&scale, &bits, sizeof scale);
  return Vec3(float(code & 511u), float((code >> 9) & 511u), float((code >> 18) & 511u)) * scale;
}
float decodeUnorm8(uint8_t v) { return float(v) * (1.0f / 255.0f); }

/// What a cone lookup reads of one voxel, decoded once (Level::coneTable).
struct ConeVoxel {
  Vec3 projected;  ///< opacity times the axis fractions (|normal| per axis at the finest level)
  Vec3 side;       ///< the normal's direction (not normalized): which side a viewer sees
  Vec3 front, back;///< radiance of the side the normal points to, and of the other
};
static_assert(sizeof(ConeVoxel) == 48, "ConeVoxel is 12 floats");

/// One level of a field: topology plus compact attributes.
struct Level {
  int level = 0;
  double voxelSize = 0.0;
  uint32_t resolution = 0;
  float invVoxelSize = 0.0f;            ///< 1 / voxelSize, for the float cone lookups
  float voxelSizeF = 0.0f;              ///< voxelSize in float
  std::unique_ptr<IndexTree> tree;      ///< brick coordinate -> brick index
  std::vector<uint64_t> brickMask;      ///< occupied voxels of the brick
  std::vector<uint32_t> brickBase;      ///< index of the brick's first voxel
  /// Levels up to kDenseBrickLevel: brick coordinate -> brick index (or -1) in a flat array of
  /// (resolution / 4)^3 entries (1 MB at level 8), so lookups need no tree probe; empty above.
  std::vector<int32_t> denseBricks;
  std::vector<Half> coverage;
  std::vector<uint16_t> normal;
  std::vector<uint8_t> albedo;          ///< 3 per voxel
  /// Surfaces are two-sided and each side keeps its own light (a panel lit from above stays
  /// dark below): RGB9E5 radiance of the front (the side the voxel's normal points to) and of
  /// the back; both empty before injection. Coarser levels: opacity-weighted means of the
  /// children's sides, after turning each child to agree with the parent's normal.
  std::vector<uint32_t> radiance;
  std::vector<uint32_t> radianceBack;
  /// Mips only: opacity-weighted mean of |normal| per axis, 3 unorm8 per voxel (the finest
  /// level takes |normal| of its one mean normal).
  std::vector<uint8_t> axisFraction;
  /// Levels up to kConeTableLevel, once their radiance is final (buildConeTable): each voxel's
  /// cone-lookup attributes decoded, so a lookup's corner is one 48-byte read instead of a half,
  /// three unorm8 (or a normalized octahedral normal), another normal and an RGB9E5 decode.
  std::vector<ConeVoxel> coneTable;
  double buildSeconds = 0.0;

  size_t size() const { return coverage.size(); }

  /// Index of voxel (i, j, k) in the attribute arrays, or -1 when inactive or outside.
  int64_t find(int64_t i, int64_t j, int64_t k, IndexAccessor& acc) const {
    if (i < 0 || j < 0 || k < 0 || i >= resolution || j >= resolution || k >= resolution) return -1;
    const int64_t brick = brickAt(int32_t(i >> 2), int32_t(j >> 2), int32_t(k >> 2), acc);
    if (brick < 0) return -1;
    const uint32_t b = uint32_t(brick);
    const uint32_t bit = voxel::brickBit(uint32_t(i), uint32_t(j), uint32_t(k));
    const uint64_t mask = brickMask[b];
    if (!((mask >> bit) & 1u)) return -1;
    return int64_t(brickBase[b]) + __builtin_popcountll(mask & ((uint64_t(1) << bit) - 1));
  }

  /// Index of brick (bi, bj, bk) (inside the level), or -1 when it has no voxel: from the flat
  /// table where there is one, else a probe of the tree.
  int64_t brickAt(int32_t bi, int32_t bj, int32_t bk, IndexAccessor& acc) const {
    if (!denseBricks.empty()) {
      const size_t side = resolution >> 2;
      return denseBricks[(size_t(bk) * side + size_t(bj)) * side + size_t(bi)];
    }
    uint32_t b = 0;
    return acc.probeValue(openvdb::Coord(bi, bj, bk), b) ? int64_t(b) : -1;
  }

  float opacity(size_t v) const { return std::min(1.0f, float(coverage[v])); }
  Vec3 albedoAt(size_t v) const {
    return Vec3(decodeUnorm8(albedo[3 * v]), decodeUnorm8(albedo[3 * v + 1]), decodeUnorm8(albedo[3 * v + 2]));
  }
  /// Both sides' radiance summed.
  Vec3 radianceAt(size_t v) const {
    return radiance.empty() ? Vec3(0.0f) : decodeRgb9e5(radiance[v]) + decodeRgb9e5(radianceBack[v]);
  }
  Vec3 normalAt(size_t v) const { return decodeNormal(normal[v]); }
  Vec3 axisFractionAt(size_t v) const {
    if (axisFraction.empty()) return glm::abs(normalAt(v));
    return Vec3(decodeUnorm8(axisFraction[3 * v]), decodeUnorm8(axisFraction[3 * v + 1]),
                decodeUnorm8(axisFraction[3 * v + 2]));
  }

  /// Visit every voxel: f(index, i, j, k), bricks in tree order (callers sort when they need
  /// an order). The brick coordinates come from the tree, so no per-brick key is stored.
  template <typename F> void forEachVoxel(F&& f) const {
    for (auto it = tree->cbeginValueOn(); it; ++it) {
      const openvdb::Coord c = it.getCoord();
      const uint32_t b = *it, bi = uint32_t(c.x()), bj = uint32_t(c.y()), bk = uint32_t(c.z());
      uint64_t mask = brickMask[b];
      size_t v = brickBase[b];
      while (mask) {
        const uint32_t bit = uint32_t(__builtin_ctzll(mask));
        mask &= mask - 1;
        f(v++, (bi << 2) | (bit >> 4), (bj << 2) | ((bit >> 2) & 3u), (bk << 2) | (bit & 3u));
      }
    }
  }

  /// Set the radiance of both sides.
  void setRadiance(const std::vector<Vec3>& values, const std::vector<Vec3>& back) {
    coneTable.clear();  // stale until buildConeTable runs again
    radiance.resize(values.size());
    for (size_t v = 0; v < values.size(); ++v) radiance[v] = encodeRgb9e5(values[v]);
    radianceBack.resize(back.size());
    for (size_t v = 0; v < back.size(); ++v) radianceBack[v] = encodeRgb9e5(back[v]);
  }

  /// Voxel v's cone-lookup attributes, decoded (coneTable's entry where there is one).
  ConeVoxel coneVoxel(size_t v) const {
    if (!coneTable.empty()) return coneTable[v];
    ConeVoxel c;
    c.projected = opacity(v) * axisFractionAt(v);
    c.side = decodeNormalDirection(normal[v]);
    c.front = radiance.empty() ? Vec3(0.0f) : decodeRgb9e5(radiance[v]);
    c.back = radianceBack.empty() ? Vec3(0.0f) : decodeRgb9e5(radianceBack[v]);
    return c;
  }
  /// Decode every voxel's cone-lookup attributes into coneTable.
  void buildConeTable() {
    coneTable.clear();
    std::vector<ConeVoxel> table(size());
    for (size_t v = 0; v < size(); ++v) table[v] = coneVoxel(v);
    coneTable = std::move(table);
  }

  uint64_t topologyBytes() const {
    return (tree ? tree->memUsage() : 0) + brickMask.capacity() * sizeof(uint64_t) +
           brickBase.capacity() * sizeof(uint32_t) + denseBricks.capacity() * sizeof(int32_t);
  }
};

/// Levels that keep a flat brick table (Level::denseBricks): 4 bytes per brick of the whole cube,
/// 1 MB at level 8; finer levels probe the tree.
constexpr int kDenseBrickLevel = 8;
/// Levels that keep decoded cone-lookup attributes (Level::coneTable, 48 bytes per voxel: 1.2 MB
/// for cornell-dragon's 25k voxels at level 6, 15 MB at level 8, so not there). Measured on
/// cornell-box at level 6: cone gathers 21% faster, the same image to 4 digits of PSNR.
constexpr int kConeTableLevel = 7;

/// Build a level's topology and compact attributes from sorted full-precision arrays.
Level makeLevel(int level, double voxelSize, const VoxelArrays& a) {
  Level out;
  out.level = level;
  out.voxelSize = voxelSize;
  out.invVoxelSize = float(1.0 / voxelSize);
  out.voxelSizeF = float(voxelSize);
  out.resolution = uint32_t(1) << level;
  out.tree = std::make_unique<IndexTree>(uint32_t(0));
  openvdb::tree::ValueAccessor<IndexTree> acc(*out.tree);
  uint64_t lastBrick = ~uint64_t(0);
  for (size_t v = 0; v < a.size(); ++v) {
    const uint64_t brick = a.keys[v] >> 6;
    if (brick != lastBrick) {
      uint32_t bi, bj, bk;
      voxel::unpackBrick(brick, bi, bj, bk);
      acc.setValue(openvdb::Coord(int32_t(bi), int32_t(bj), int32_t(bk)), uint32_t(out.brickMask.size()));
      lastBrick = brick;
      out.brickMask.push_back(0);
      out.brickBase.push_back(uint32_t(v));
    }
    out.brickMask.back() |= uint64_t(1) << (a.keys[v] & 63u);
  }
  out.brickMask.shrink_to_fit();
  out.brickBase.shrink_to_fit();
  if (level <= kDenseBrickLevel) {
    const size_t side = out.resolution >> 2;
    out.denseBricks.assign(std::max<size_t>(1, side * side * side), -1);
    for (auto it = out.tree->cbeginValueOn(); it; ++it) {
      const openvdb::Coord c = it.getCoord();
      out.denseBricks[(size_t(c.z()) * side + size_t(c.y())) * side + size_t(c.x())] = int32_t(*it);
    }
  }
  out.coverage.resize(a.size());
  out.normal.resize(a.size());
  // Albedo is kept at the finest level only: injection reads it there, and nothing samples
  // the albedo of coarser levels (cones gather outgoing radiance).
  out.albedo.resize(a.albedo.empty() ? 0 : 3 * a.size());
  for (size_t v = 0; v < a.size(); ++v) {
    out.coverage[v] = Half(a.coverage[v]);
    out.normal[v] = encodeNormal(a.normal[v]);
    if (!a.albedo.empty())
      for (int c = 0; c < 3; ++c) out.albedo[3 * v + c] = encodeUnorm8(a.albedo[v][c]);
  }
  if (!a.radiance.empty()) out.setRadiance(a.radiance, a.radianceBack);
  out.axisFraction.resize(3 * a.axisFraction.size());
  for (size_t v = 0; v < a.axisFraction.size(); ++v)
    for (int c = 0; c < 3; ++c) out.axisFraction[3 * v + c] = encodeUnorm8(a.axisFraction[v][c]);
  return out;
}

/// 2x2x2 box restriction of `child` (parent (i, j, k) = child (i, j, k) >> 1): opacity = sum of
/// child opacities / 8; no albedo (see makeLevel). Surfaces are two-sided, so each child is
/// first turned to agree with the most opaque child's normal (its front and back swapped when
/// turned); normal = opacity-weighted sum of the turned normals, renormalized; front and back
/// radiance = opacity-weighted means (sum(opacity * radiance) * voxel volume is preserved before
/// storage). For cones: axisFraction = opacity-weighted mean |normal| per axis.
/// The weight a child voxel gives one parent, per axis, in eighths: box 4 (its own parent
/// only, 4/8 per axis = 1/8 in 3D); Gaussian 3 to its own parent and 1 to the parent beside it
/// on its side (the binomial [1 3 3 1] / 8 over the 4 children nearest the parent's centre).
/// Either way a child's weights sum to 1/8 and a parent's to 1: coverage and flux are
/// conserved, and a plane stays one crossing (VoxelSample::projected) at every level.
struct ChildShare {
  uint64_t parent;
  uint32_t child;
  float weight;
  bool operator<(const ChildShare& o) const { return parent != o.parent ? parent < o.parent : child < o.child; }
};

/// Every (parent, child, weight) share of `child`'s voxels, sorted by (parent key, child index),
/// which is unique: one order at any thread count.
std::vector<ChildShare> childShares(const Level& child, MipFilter filter) {
  std::vector<ChildShare> shares;
  const uint32_t parentRes = std::max(1u, child.resolution >> 1);
  if (filter == MipFilter::Box) {
    shares.reserve(child.size());
    child.forEachVoxel([&](size_t v, uint32_t i, uint32_t j, uint32_t k) {
      shares.push_back({voxel::packKey(i >> 1, j >> 1, k >> 1), uint32_t(v), 0.125f});
    });
    tbb::parallel_sort(shares.begin(), shares.end());
    return shares;
  }
  shares.reserve(child.size() * 8);
  child.forEachVoxel([&](size_t v, uint32_t i, uint32_t j, uint32_t k) {
    const uint32_t c[3] = {i, j, k};
    uint32_t own[3], other[3];
    for (int a = 0; a < 3; ++a) {
      own[a] = c[a] >> 1;
      // An even child lies on its parent's low side, next to the parent below. At the
      // field's faces the neighbour does not exist: its share goes to the own parent.
      const int64_t n = (c[a] & 1u) ? int64_t(own[a]) + 1 : int64_t(own[a]) - 1;
      other[a] = n < 0 || n >= int64_t(parentRes) ? own[a] : uint32_t(n);
    }
    for (int corner = 0; corner < 8; ++corner) {
      uint32_t q[3];
      float w = 1.0f;
      for (int a = 0; a < 3; ++a) {
        const bool side = (corner >> a) & 1;
        q[a] = side ? other[a] : own[a];
        w *= side ? 0.125f : 0.375f;
      }
      shares.push_back({voxel::packKey(q[0], q[1], q[2]), uint32_t(v), w});
    }
  });
  // A child whose neighbour was folded back names its own parent twice: merge those.
  tbb::parallel_sort(shares.begin(), shares.end());
  size_t out = 0;
  for (size_t s = 0; s < shares.size(); ++s) {
    if (out > 0 && shares[out - 1].parent == shares[s].parent && shares[out - 1].child == shares[s].child)
      shares[out - 1].weight += shares[s].weight;
    else
      shares[out++] = shares[s];
  }
  shares.resize(out);
  return shares;
}

/// One coarser level from `child` (VoxelField::buildMips).
VoxelArrays restrictLevel(const Level& child, MipFilter filter) {
  const std::vector<ChildShare> shares = childShares(child, filter);
  VoxelArrays out;
  const bool lit = !child.radiance.empty();
  for (size_t a = 0; a < shares.size();) {
    size_t end = a;
    size_t ref = a;  // the child that weighs most: the others turn to agree with it
    for (; end < shares.size() && shares[end].parent == shares[a].parent; ++end)
      if (shares[end].weight * child.opacity(shares[end].child) > shares[ref].weight * child.opacity(shares[ref].child))
        ref = end;
    const Vec3 refNormal = child.normalAt(shares[ref].child);
    double opSum = 0.0;
    DVec3 front(0.0), back(0.0), nrm(0.0), axes(0.0);
    for (size_t b = a; b < end; ++b) {
      const size_t c = shares[b].child;
      const double op = double(shares[b].weight) * child.opacity(c);
      const Vec3 n = child.normalAt(c);
      const bool turned = glm::dot(n, refNormal) < 0.0f;
      opSum += op;
      nrm += op * DVec3(turned ? -n : n);
      axes += op * DVec3(child.axisFractionAt(c));
      if (lit) {
        const DVec3 f = DVec3(decodeRgb9e5(child.radiance[c])), k = DVec3(decodeRgb9e5(child.radianceBack[c]));
        front += op * (turned ? k : f);
        back += op * (turned ? f : k);
      }
    }
    const double len = glm::length(nrm);
    out.keys.push_back(shares[a].parent);
    out.coverage.push_back(float(opSum));
    out.axisFraction.push_back(opSum > 0.0 ? Vec3(axes / opSum) : Vec3(0.0f));
    out.normal.push_back(len > 0.0 ? Vec3(nrm / len) : refNormal);
    if (lit) {
      out.radiance.push_back(opSum > 0.0 ? Vec3(front / opSum) : Vec3(0.0f));
      out.radianceBack.push_back(opSum > 0.0 ? Vec3(back / opSum) : Vec3(0.0f));
    }
    a = end;
  }
  return out;
}

/// A field's levels, finest first.
struct Grid {
  std::vector<Level> levels;
  double injectSeconds = 0.0;
  bool empty() const { return levels.empty(); }
  const Level* find(int level) const {
    if (levels.empty()) return nullptr;
    const int m = levels.front().level - level;
    return m >= 0 && m < int(levels.size()) ? &levels[size_t(m)] : nullptr;
  }
};

/// What a trilinear or nearest query accumulates.
struct Accum {
  double weight = 0.0;  ///< sum of filter weight * opacity
  double opacity = 0.0; ///< sum of filter weight * opacity (same, kept apart for clarity)
  DVec3 radiance{0.0};  ///< sum of filter weight * opacity * radiance
  DVec3 normal{0.0};    ///< sum of filter weight * opacity * normal
  DVec3 projected{0.0}; ///< sum of filter weight * opacity * |normal| per axis
  VoxelSample finish() const {
    VoxelSample s;
    s.opacity = float(opacity);
    s.projected = Vec3(projected);
    if (weight > 0.0) {
      s.radiance = Vec3(radiance / weight);
      s.normal = Vec3(normal / weight);
    }
    return s;
  }
};

/// Trilinear over the 8 voxel centres around worldPos (inactive voxels count as empty).
void trilinear(const Level& lv, const DVec3& origin, const Vec3& worldPos, double scale, Accum& acc) {
  const DVec3 q = (DVec3(worldPos) - origin) / lv.voxelSize - DVec3(0.5);
  const DVec3 base = glm::floor(q);
  const DVec3 f = q - base;
  IndexAccessor access(*lv.tree);
  for (int c = 0; c < 8; ++c) {
    const int dx = c & 1, dy = (c >> 1) & 1, dz = (c >> 2) & 1;
    const double w = (dx ? f.x : 1.0 - f.x) * (dy ? f.y : 1.0 - f.y) * (dz ? f.z : 1.0 - f.z) * scale;
    if (w <= 0.0) continue;
    const int64_t v = lv.find(int64_t(base.x) + dx, int64_t(base.y) + dy, int64_t(base.z) + dz, access);
    if (v < 0) continue;
    const double wo = w * lv.opacity(size_t(v));
    acc.weight += wo;
    acc.opacity += wo;
    acc.radiance += wo * DVec3(lv.radianceAt(size_t(v)));
    acc.normal += wo * DVec3(lv.normalAt(size_t(v)));
    const DVec3 proj = wo * DVec3(lv.axisFractionAt(size_t(v)));
    acc.projected += proj;
  }
}

/// The cone's part of a trilinear lookup (VoxelField::coneSample), in float, normals decoded
/// only for their side (not normalized): the 8 corners' bricks are probed once each (most
/// lookups fall in one brick).
void coneTrilinear(const Level& lv, const Vec3& localPos, float scale, const Vec3& d, const Vec3& localApex,
                   float& density, Vec3& radiance) {
  const Vec3 absD = glm::abs(d);
  const Vec3 q = localPos * lv.invVoxelSize - Vec3(0.5f);
  const Vec3 base = glm::floor(q);
  const Vec3 f = q - base;
  const int32_t i0 = int32_t(base.x), j0 = int32_t(base.y), k0 = int32_t(base.z);
  const int32_t res = int32_t(lv.resolution);
  IndexAccessor access(*lv.tree);  // unused where the level has a flat brick table
  // Bricks of the corners: (i0 + d) >> 2 is i0 >> 2 or one more, per axis. -2: not probed yet.
  int64_t bricks[8] = {-2, -2, -2, -2, -2, -2, -2, -2};
  for (int c = 0; c < 8; ++c) {
    const int dx = c & 1, dy = (c >> 1) & 1, dz = (c >> 2) & 1;
    const float w = (dx ? f.x : 1.0f - f.x) * (dy ? f.y : 1.0f - f.y) * (dz ? f.z : 1.0f - f.z) * scale;
    if (w <= 0.0f) continue;
    const int32_t i = i0 + dx, j = j0 + dy, k = k0 + dz;
    if (i < 0 || j < 0 || k < 0 || i >= res || j >= res || k >= res) continue;
    const int slot = ((i >> 2) - (i0 >> 2)) | (((j >> 2) - (j0 >> 2)) << 1) | (((k >> 2) - (k0 >> 2)) << 2);
    int64_t& b = bricks[slot];
    if (b == -2) b = lv.brickAt(i >> 2, j >> 2, k >> 2, access);
    if (b < 0) continue;
    const uint32_t bit = voxel::brickBit(uint32_t(i), uint32_t(j), uint32_t(k));
    const uint64_t mask = lv.brickMask[size_t(b)];
    if (!((mask >> bit) & 1u)) continue;
    const size_t v = lv.brickBase[size_t(b)] + size_t(__builtin_popcountll(mask & ((uint64_t(1) << bit) - 1)));
    // Projected area along the cone's direction, and the radiance of the side the apex sees
    // (the direction from the apex, not the axis: a lookup's reach takes in surfaces beside
    // the axis, and a ray from the apex reaches them from their apex side).
    const Vec3 centre = (Vec3(float(i), float(j), float(k)) + Vec3(0.5f)) * lv.voxelSizeF;
    const ConeVoxel cv = lv.coneVoxel(v);
    const Vec3 proj = cv.projected * absD;
    const float area = w * (proj.x + proj.y + proj.z);
    density += area;
    radiance += area * (glm::dot(cv.side, centre - localApex) <= 0.0f ? cv.front : cv.back);
  }
}

/// A read-only concatenation of photon lists (the main grid takes the global and the caustic map).
struct PhotonList {
  std::vector<const std::vector<Photon>*> parts;
  size_t size() const {
    size_t n = 0;
    for (const auto* p : parts) n += p->size();
    return n;
  }
  const Photon& operator[](size_t i) const {
    for (const auto* p : parts) {
      if (i < p->size()) return (*p)[i];
      i -= p->size();
    }
    return parts.back()->back();  // unreachable for i < size()
  }
};

std::once_flag g_openvdbInit;

}  // namespace

struct VoxelField::Impl {
  VoxelSettings settings;
  Bounds3 bounds;
  DVec3 origin{0.0};
  Vec3 originF{0.0f};         ///< origin in float, for the cone lookups
  double extent = 0.0;        ///< side of the cube the grid covers, world units
  Grid main, caustic;
  double surfaceArea = 0.0;   ///< world units^2, full precision sum at voxelization
  DVec3 injected{0.0}, dropped{0.0};
  uint64_t globalPhotons = 0, causticPhotons = 0;

  double voxelSize(int level) const { return extent / double(uint64_t(1) << level); }
  void inject(Grid& grid, const PhotonList& photons, Progress* progress, DVec3& injectedOut);
};

namespace {

/// Flux per voxel and side (front: the side the voxel's normal points to).
struct SidedFlux {
  std::vector<Vec3> front, back;
};

/// The footprint spreads a photon over the surface it landed on: a voxel whose mean normal
/// turns more than 60 degrees from the photon's belongs to another surface across a crease (a
/// wall beside a lit floor), not to this one; a corner voxel's 45 degrees still counts.
constexpr float kSameSurfaceCos = 0.5f;

/// Splat `photons` into `lv` (see VoxelField::inject); returns flux per voxel and side.
SidedFlux splatPhotons(const Level& lv, const DVec3& origin, const PhotonList& photons, float sigmaVoxels,
                       DVec3& dropped, Progress* progress) {
  SidedFlux flux{std::vector<Vec3>(lv.size(), Vec3(0.0f)), std::vector<Vec3>(lv.size(), Vec3(0.0f))};
  const double radius = 3.0 * double(sigmaVoxels);
  const double inv2s2 = 1.0 / (2.0 * double(sigmaVoxels) * sigmaVoxels);
  // Photons go in fixed blocks; a wave of blocks is splatted in parallel into per-block lists,
  // then added in block order, so the float sums are the same at any thread count.
  constexpr size_t kBlock = 2048, kWave = 64;
  const size_t blocks = (photons.size() + kBlock - 1) / kBlock;
  struct Splat {
    uint32_t voxel;
    bool back;
    Vec3 flux;
  };
  std::vector<std::vector<Splat>> lists(std::min(blocks, kWave));
  std::vector<DVec3> blockDropped(lists.size());
  // Each voxel's normal direction, decoded once, and |n|^2 (-1: no diffuse surface, which gathers
  // no light): 125 voxels are tried per photon.
  std::vector<glm::vec4> surface(lv.size());
  tbb::parallel_for(size_t(0), lv.size(), [&](size_t v) {
    const uint8_t* alb = &lv.albedo[3 * v];
    const Vec3 n = decodeNormalDirection(lv.normal[v]);
    surface[v] = glm::vec4(n, (alb[0] | alb[1] | alb[2]) == 0 ? -1.0f : glm::dot(n, n));
  });
  for (size_t wave = 0; wave < blocks; wave += kWave) {
    if (progress && progress->cancelled()) throw CancelledError();
    const size_t waveBlocks = std::min(kWave, blocks - wave);
    tbb::parallel_for(size_t(0), waveBlocks, [&](size_t wb) {
      std::vector<Splat>& out = lists[wb];
      out.clear();
      blockDropped[wb] = DVec3(0.0);
      IndexAccessor access(*lv.tree);
      struct Candidate {
        uint32_t voxel;
        float weight;
      };
      // Voxels whose (wound) normal faces the photon, and those facing away from it.
      std::vector<Candidate> cand[2];
      std::vector<double> gauss[3];
      const size_t begin = (wave + wb) * kBlock, end = std::min(photons.size(), begin + kBlock);
      for (size_t p = begin; p < end; ++p) {
        const Photon& ph = photons[p];
        const DVec3 q = (DVec3(ph.position) - origin) / lv.voxelSize;
        cand[0].clear();
        cand[1].clear();
        double wsum[2] = {0.0, 0.0};
        int64_t lo[3], hi[3];
        for (int a = 0; a < 3; ++a) {
          lo[a] = int64_t(std::ceil(q[a] - 0.5 - radius));
          hi[a] = int64_t(std::floor(q[a] - 0.5 + radius));
          // The Gaussian is separable: one exp per voxel row instead of one per voxel.
          gauss[a].clear();
          for (int64_t i = lo[a]; i <= hi[a]; ++i) gauss[a].push_back(std::exp(-sqr(double(i) + 0.5 - q[a]) * inv2s2));
        }
        for (int64_t i = lo[0]; i <= hi[0]; ++i)
          for (int64_t j = lo[1]; j <= hi[1]; ++j)
            for (int64_t k = lo[2]; k <= hi[2]; ++k) {
              const double d2 = sqr(double(i) + 0.5 - q.x) + sqr(double(j) + 0.5 - q.y) + sqr(double(k) + 0.5 - q.z);
              if (d2 > radius * radius) continue;
              const int64_t v = lv.find(i, j, k, access);
              if (v < 0) continue;
              // Only voxels holding diffuse surface gather light.
              const glm::vec4& sv = surface[size_t(v)];
              if (sv.w < 0.0f) continue;
              // Voxels of another surface (kSameSurfaceCos) take none of the photon.
              const float cosNormals = glm::dot(Vec3(sv), ph.normal);
              if (sqr(cosNormals) <= sqr(kSameSurfaceCos) * sv.w) continue;
              // Gaussian footprint times the surface area the voxel holds: a uniform photon
              // density then gives a uniform irradiance flux / area, where the plain Gaussian
              // would give a voxel clipped to a sliver of surface the flux of a full voxel (and
              // radiance up to 1 / sliver area).
              const double g = gauss[0][size_t(i - lo[0])] * gauss[1][size_t(j - lo[1])] * gauss[2][size_t(k - lo[2])];
              const double w = g * double(lv.coverage[size_t(v)]);
              const int back = cosNormals < 0.0f;
              cand[back].push_back({uint32_t(v), float(w)});
              wsum[back] += w;
            }
        // The photon lands on the side it arrived on: the front of the voxels that face it (a
        // closed object's far face, in the next voxel layer, stays dark inside), or, where none
        // does, the back of those facing away (an open panel lit from behind its winding).
        // Normalized over the chosen voxels: the photon's power is conserved.
        const int side = wsum[0] > 0.0 ? 0 : 1;
        if (wsum[side] > 0.0) {
          for (const Candidate& c : cand[side])
            out.push_back({c.voxel, side == 1, ph.power * float(double(c.weight) / wsum[side])});
          continue;
        }
        const int64_t v = lv.find(int64_t(std::floor(q.x)), int64_t(std::floor(q.y)), int64_t(std::floor(q.z)), access);
        if (v >= 0)
          out.push_back({uint32_t(v), glm::dot(decodeNormalDirection(lv.normal[size_t(v)]), ph.normal) < 0.0f, ph.power});
        else blockDropped[wb] += DVec3(ph.power);
      }
    });
    for (size_t wb = 0; wb < waveBlocks; ++wb) {
      for (const Splat& s : lists[wb]) (s.back ? flux.back : flux.front)[s.voxel] += s.flux;
      dropped += blockDropped[wb];
    }
    if (progress) progress->advance(std::min(photons.size(), (wave + waveBlocks) * kBlock) - wave * kBlock);
  }
  return flux;
}

}  // namespace

/// The voxels of `lv` with nonzero radiance, as a level of their own.
Level keepLit(const Level& lv) {
  std::vector<std::pair<uint64_t, uint32_t>> lit;
  lv.forEachVoxel([&](size_t v, uint32_t i, uint32_t j, uint32_t k) {
    if (!isBlack(lv.radianceAt(v))) lit.emplace_back(voxel::packKey(i, j, k), uint32_t(v));
  });
  std::sort(lit.begin(), lit.end());
  VoxelArrays a;
  for (const auto& [key, v] : lit) {
    a.keys.push_back(key);
    a.coverage.push_back(float(lv.coverage[v]));
    a.normal.push_back(lv.normalAt(v));
    a.albedo.push_back(lv.albedoAt(v));
    a.radiance.push_back(decodeRgb9e5(lv.radiance[v]));
    a.radianceBack.push_back(decodeRgb9e5(lv.radianceBack[v]));
  }
  Level out = makeLevel(lv.level, lv.voxelSize, a);
  out.buildSeconds = lv.buildSeconds;
  return out;
}

void VoxelField::Impl::inject(Grid& grid, const PhotonList& photons, Progress* progress, DVec3& injectedOut) {
  if (grid.empty()) return;
  Timer timer;
  Level& lv = grid.levels.front();
  const SidedFlux flux = splatPhotons(lv, origin, photons, settings.kernelSigmaVoxels, dropped, progress);
  // L = albedo / pi * E per side, E = flux / area (area = coverage * voxelSize^2 at the finest
  // level: each side of a two-sided surface has all of it).
  std::vector<Vec3> front(lv.size()), back(lv.size());
  const double voxelArea = lv.voxelSize * lv.voxelSize;
  injectedOut = DVec3(0.0);
  for (size_t v = 0; v < lv.size(); ++v) {
    injectedOut += DVec3(flux.front[v]) + DVec3(flux.back[v]);
    const double area = double(lv.coverage[v]) * voxelArea;
    if (!(area > 0.0)) continue;
    const DVec3 k = DVec3(lv.albedoAt(v)) * (1.0 / (3.14159265358979323846 * area));
    front[v] = Vec3(k * DVec3(flux.front[v]));
    back[v] = Vec3(k * DVec3(flux.back[v]));
  }
  lv.setRadiance(front, back);
  // Mips built before are stale: dropped, buildMips makes them anew (rebuilding them here too
  // built every mip twice per pass of a progressive render).
  grid.levels.resize(1);
  grid.injectSeconds = timer.seconds();
}

VoxelField::VoxelField() : m_impl(std::make_unique<Impl>()) {}
VoxelField::~VoxelField() = default;
VoxelField::VoxelField(VoxelField&&) noexcept = default;
VoxelField& VoxelField::operator=(VoxelField&&) noexcept = default;

VoxelField VoxelField::voxelize(const Scene& scene, const VoxelSettings& settings, Progress* progress,
                                const std::vector<Photon>* causticPhotons) {
  if (settings.level < 1 || settings.level > 13)
    throw SettingsError("voxel level must be in [1, 13], got " + std::to_string(settings.level));
  if (settings.coarsestLevel < 0 || settings.coarsestLevel > settings.level)
    throw SettingsError("coarsest voxel level must be in [0, level], got " + std::to_string(settings.coarsestLevel));
  if (!(settings.kernelSigmaVoxels > 0.0f) || settings.kernelSigmaVoxels > 16.0f)
    throw SettingsError("kernel sigma must be in (0, 16] voxels, got " + std::to_string(settings.kernelSigmaVoxels));
  if (settings.causticLevel != 0 && (settings.causticLevel < settings.coarsestLevel || settings.causticLevel > 13))
    throw SettingsError("caustic level must be 0 or in [coarsest level, 13], got " +
                        std::to_string(settings.causticLevel));
  if (scene.triangleCount() == 0 || scene.bounds().empty()) throw SettingsError("cannot voxelize a scene without triangles");
  if (std::all_of(scene.triMaterial.begin(), scene.triMaterial.end(),
                  [&](uint32_t m) { return scene.materials[m].type == MaterialType::Dielectric; }))
    throw SettingsError("cannot voxelize a scene of smooth glass alone: the field holds no glass (nothing to gather)");
  if (!(settings.padding >= 0.0 && settings.padding <= 1.0))
    throw SettingsError("field padding must be in [0, 1] (a fraction of the scene's side), got " +
                        std::to_string(settings.padding));

  VoxelField field;
  Impl& f = *field.m_impl;
  f.settings = settings;
  const Bounds3& sb = scene.bounds();
  const DVec3 diag = DVec3(sb.hi) - DVec3(sb.lo);
  const double side = std::max(diag.x, std::max(diag.y, diag.z));
  const double pad = settings.padding * side;
  f.origin = DVec3(sb.lo) - DVec3(pad);
  f.originF = Vec3(f.origin);
  // Pad by a relative 1e-6 so the max corner falls inside the last voxel, not on its far face.
  f.extent = (side + 2.0 * pad) * (1.0 + 1e-6);
  if (!(f.extent > 0.0)) throw SettingsError("cannot voxelize a scene of zero extent");
  f.bounds = Bounds3(Vec3(f.origin), Vec3(f.origin + DVec3(f.extent)));

  auto build = [&](Grid& grid, int level, bool countArea, const std::vector<uint64_t>* onlyBricks) {
    Timer timer;
    const double vs = f.voxelSize(level);
    VoxelArrays a = voxel::voxelizeTriangles(scene, f.origin, vs, uint32_t(1) << level, progress, onlyBricks);
    if (countArea) {
      double area = 0.0;
      for (float c : a.coverage) area += double(c);
      f.surfaceArea = area * vs * vs;
    }
    grid.levels.push_back(makeLevel(level, vs, a));
    grid.levels.back().buildSeconds = timer.seconds();
  };
  build(f.main, settings.level, true, nullptr);
  if (settings.causticLevel > 0) {
    if (!causticPhotons) {
      build(f.caustic, settings.causticLevel, false, nullptr);
      return field;
    }
    // The bricks the photons' footprints reach (splatPhotons' voxel box around each, which
    // holds the nearest-voxel fallback too): the caustic grid keeps only voxels a caustic
    // photon lit, so voxelizing the rest of the scene at the caustic level (0.2 s on the
    // dragon at level 7, for 600 stored photons) changes nothing.
    const double vs = f.voxelSize(settings.causticLevel);
    const double radius = 3.0 * double(settings.kernelSigmaVoxels);
    const int64_t maxIndex = (int64_t(1) << settings.causticLevel) - 1;
    std::vector<uint64_t> bricks;
    for (const Photon& ph : *causticPhotons) {
      const DVec3 q = (DVec3(ph.position) - f.origin) / vs;
      int64_t lo[3], hi[3];
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::clamp(int64_t(std::floor(q[a] - 0.5 - radius)), int64_t(0), maxIndex) >> voxel::kBrickLog2;
        hi[a] = std::clamp(int64_t(std::floor(q[a] + 0.5 + radius)), int64_t(0), maxIndex) >> voxel::kBrickLog2;
      }
      for (int64_t bi = lo[0]; bi <= hi[0]; ++bi)
        for (int64_t bj = lo[1]; bj <= hi[1]; ++bj)
          for (int64_t bk = lo[2]; bk <= hi[2]; ++bk) bricks.push_back(voxel::packBrick(uint32_t(bi), uint32_t(bj), uint32_t(bk)));
    }
    std::sort(bricks.begin(), bricks.end());
    bricks.erase(std::unique(bricks.begin(), bricks.end()), bricks.end());
    build(f.caustic, settings.causticLevel, false, &bricks);
  }
  return field;
}

void VoxelField::inject(const PhotonMaps& photons, Progress* progress) {
  Impl& f = *m_impl;
  if (progress) progress->start("inject", photons.global.size() + photons.caustic.size());
  f.dropped = DVec3(0.0);
  f.globalPhotons = photons.global.size();
  f.causticPhotons = f.caustic.empty() ? 0 : photons.caustic.size();
  // The main grid holds all diffuse radiance: global photons (every path but L S+ D) plus
  // caustic photons (L S+ D): each pass carries the lights' full flux for its own paths.
  f.inject(f.main, PhotonList{{&photons.global, &photons.caustic}}, progress, f.injected);
  DVec3 causticInjected(0.0);
  if (!f.caustic.empty()) {
    // The caustic grid is voxelized fully so that any caustic photon finds its surface; after
    // injection only the voxels a caustic photon reached are kept (model no more than the
    // scene needs), and it gets no mips: caustics are gathered at the shading point.
    f.caustic.levels.resize(1);
    f.inject(f.caustic, PhotonList{{&photons.caustic}}, progress, causticInjected);
    f.caustic.levels.front() = keepLit(f.caustic.levels.front());
  }
  if (progress) progress->finish();
}

void VoxelField::buildMips(Progress* progress) {
  Impl& f = *m_impl;
  for (Grid* grid : {&f.main}) {
    if (grid->empty()) continue;
    grid->levels.resize(1);
    if (progress) progress->start("mips", uint64_t(grid->levels.front().level - f.settings.coarsestLevel));
    while (grid->levels.back().level > f.settings.coarsestLevel) {
      if (progress && progress->cancelled()) throw CancelledError();
      Timer t;
      const Level& child = grid->levels.back();
      VoxelArrays a = restrictLevel(child, f.settings.mipFilter);
      const int level = child.level - 1;
      const double vs = child.voxelSize * 2.0;
      grid->levels.push_back(makeLevel(level, vs, a));
      grid->levels.back().buildSeconds = t.seconds();
      if (progress) progress->advance(1);
    }
    if (progress) progress->finish();
  }
  // Radiance is final now: decode what the cone lookups read, at the coarser levels.
  for (Grid* grid : {&f.main, &f.caustic})
    for (Level& lv : grid->levels)
      if (lv.level <= kConeTableLevel) lv.buildConeTable();
}

const VoxelSettings& VoxelField::settings() const { return m_impl->settings; }
const Bounds3& VoxelField::bounds() const { return m_impl->bounds; }
double VoxelField::voxelSize(int level) const { return m_impl->voxelSize(level); }

std::vector<int> VoxelField::levels() const {
  std::vector<int> out;
  for (const Level& lv : m_impl->main.levels) out.push_back(lv.level);
  return out;
}

VoxelSample VoxelField::lookup(const Vec3& worldPos, int level) const {
  const Level* lv = m_impl->main.find(level);
  if (!lv) return {};
  const DVec3 q = glm::floor((DVec3(worldPos) - m_impl->origin) / lv->voxelSize);
  IndexAccessor access(*lv->tree);
  const int64_t v = lv->find(int64_t(q.x), int64_t(q.y), int64_t(q.z), access);
  if (v < 0) return {};
  VoxelSample s;
  s.opacity = lv->opacity(size_t(v));
  s.projected = s.opacity * lv->axisFractionAt(size_t(v));
  s.radiance = lv->radianceAt(size_t(v));
  s.normal = lv->normalAt(size_t(v));
  return s;
}

VoxelSample VoxelField::sample(const Vec3& worldPos, float level) const {
  const Grid& g = m_impl->main;
  if (g.empty()) return {};
  const float finest = float(g.levels.front().level), coarsest = float(g.levels.back().level);
  const float l = std::clamp(level, coarsest, finest);
  const int l0 = int(std::floor(l));
  const float t = l - float(l0);
  Accum acc;
  trilinear(*g.find(l0), m_impl->origin, worldPos, 1.0 - double(t), acc);
  if (t > 0.0f) trilinear(*g.find(l0 + 1), m_impl->origin, worldPos, double(t), acc);
  return acc.finish();
}

ConeSample VoxelField::coneSample(const Vec3& worldPos, float level, const Vec3& dir, const Vec3& apex) const {
  const Grid& g = m_impl->main;
  ConeSample out;
  if (g.empty()) return out;
  const float finest = float(g.levels.front().level), coarsest = float(g.levels.back().level);
  const float l = std::clamp(level, coarsest, finest);
  const int l0 = int(std::floor(l));
  const float t = l - float(l0);
  const Vec3 local = worldPos - m_impl->originF;
  const Vec3 localApex = apex - m_impl->originF;
  coneTrilinear(*g.find(l0), local, 1.0f - t, dir, localApex, out.density, out.radiance);
  if (t > 0.0f) coneTrilinear(*g.find(l0 + 1), local, t, dir, localApex, out.density, out.radiance);
  if (out.density > 0.0f) out.radiance /= out.density;
  return out;
}

Vec3 VoxelField::causticRadiance(const Vec3& worldPos, const Vec3& viewFrom) const {
  const Grid& g = m_impl->caustic;
  if (g.empty()) return Vec3(0.0f);
  // The projected-area-weighted mean of the faces seen from viewFrom: the surface's caustic
  // radiance on the viewer's side, not faded by the trilinear weights of empty voxels around it.
  float density = 0.0f;
  Vec3 radiance(0.0f);
  const Vec3 dir = glm::normalize(worldPos - viewFrom);
  coneTrilinear(g.levels.front(), worldPos - m_impl->originF, 1.0f, dir, viewFrom - m_impl->originF, density, radiance);
  return density > 0.0f ? radiance / density : Vec3(0.0f);
}

Vec3 VoxelField::injectedPower() const { return Vec3(m_impl->injected); }
Vec3 VoxelField::droppedPower() const { return Vec3(m_impl->dropped); }
double VoxelField::surfaceArea() const { return m_impl->surfaceArea; }

uint64_t VoxelField::activeVoxels(int level) const {
  const Level* lv = m_impl->main.find(level);
  return lv ? lv->size() : 0;
}

std::vector<VoxelGridStats> VoxelField::stats() const {
  std::vector<VoxelGridStats> rows;
  for (const Level& lv : m_impl->main.levels) {
    auto row = [&](const char* name, uint64_t bytes, double seconds) {
      VoxelGridStats s;
      s.grid = name;
      s.level = lv.level;
      s.voxelSize = lv.voxelSize;
      s.activeVoxels = lv.size();
      s.leaves = lv.tree ? lv.tree->leafCount() : 0;
      s.bytes = bytes;
      s.seconds = seconds;
      rows.push_back(s);
    };
    const bool finest = &lv == &m_impl->main.levels.front();
    row("topology", lv.topologyBytes(), lv.buildSeconds);
    row("opacity", lv.coverage.capacity() * sizeof(Half), 0.0);
    row("normal", lv.normal.capacity() * sizeof(uint16_t), 0.0);
    if (!lv.axisFraction.empty()) row("axes", lv.axisFraction.capacity() * sizeof(uint8_t), 0.0);
    if (!lv.albedo.empty()) row("albedo", lv.albedo.capacity() * sizeof(uint8_t), 0.0);
    row("radiance", lv.radiance.capacity() * sizeof(uint32_t), finest ? m_impl->main.injectSeconds : 0.0);
    if (!lv.radianceBack.empty()) row("radiance_back", lv.radianceBack.capacity() * sizeof(uint32_t), 0.0);
    if (!lv.coneTable.empty()) row("cone_table", lv.coneTable.capacity() * sizeof(ConeVoxel), 0.0);
  }
  for (const Level& lv : m_impl->caustic.levels) {
    VoxelGridStats s;
    s.grid = "caustic";
    s.level = lv.level;
    s.voxelSize = lv.voxelSize;
    s.activeVoxels = lv.size();
    s.leaves = lv.tree ? lv.tree->leafCount() : 0;
    s.bytes = lv.topologyBytes() + lv.coverage.capacity() * sizeof(Half) + lv.normal.capacity() * sizeof(uint16_t) +
              lv.albedo.capacity() + (lv.radiance.capacity() + lv.radianceBack.capacity()) * sizeof(uint32_t) +
              lv.coneTable.capacity() * sizeof(ConeVoxel);
    s.seconds = lv.buildSeconds;
    rows.push_back(s);
  }
  return rows;
}

uint64_t VoxelField::memoryBytes() const {
  uint64_t total = 0;
  for (const VoxelGridStats& s : stats()) total += s.bytes;
  return total;
}

void VoxelField::write(const std::string& path, const nlohmann::json& metadata) const {
  std::call_once(g_openvdbInit, [] { openvdb::initialize(); });
  const Impl& f = *m_impl;
  openvdb::GridPtrVec grids;
  auto transformFor = [&](const Level& lv) {
    // OpenVDB puts voxel centres at integer index coordinates: voxel (i, j, k) of ours has its
    // centre at origin + (i + 0.5) * voxelSize.
    auto xform = openvdb::math::Transform::createLinearTransform(lv.voxelSize);
    xform->postTranslate(openvdb::Vec3d(f.origin.x, f.origin.y, f.origin.z) + openvdb::Vec3d(0.5 * lv.voxelSize));
    return xform;
  };
  auto floatGrid = [&](const Level& lv, const std::string& name, auto&& value) {
    auto grid = openvdb::FloatGrid::create(0.0f);
    grid->setName(name);
    grid->setTransform(transformFor(lv));
    grid->setGridClass(openvdb::GRID_FOG_VOLUME);
    auto acc = grid->getAccessor();
    lv.forEachVoxel([&](size_t v, uint32_t i, uint32_t j, uint32_t k) {
      acc.setValue(openvdb::Coord(int32_t(i), int32_t(j), int32_t(k)), value(v));
    });
    grids.push_back(grid);
  };
  auto vecGrid = [&](const Level& lv, const std::string& name, auto&& value) {
    auto grid = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.0f));
    grid->setName(name);
    grid->setTransform(transformFor(lv));
    auto acc = grid->getAccessor();
    lv.forEachVoxel([&](size_t v, uint32_t i, uint32_t j, uint32_t k) {
      const Vec3 x = value(v);
      acc.setValue(openvdb::Coord(int32_t(i), int32_t(j), int32_t(k)), openvdb::Vec3s(x.x, x.y, x.z));
    });
    grids.push_back(grid);
  };
  for (const Level& lv : f.main.levels) {
    const std::string l = std::to_string(lv.level);
    floatGrid(lv, "opacity_L" + l, [&](size_t v) { return lv.opacity(v); });
    vecGrid(lv, "normal_L" + l, [&](size_t v) { return lv.normalAt(v); });
    if (!lv.albedo.empty()) vecGrid(lv, "albedo_L" + l, [&](size_t v) { return lv.albedoAt(v); });
    vecGrid(lv, "radiance_L" + l, [&](size_t v) { return lv.radianceAt(v); });
  }
  for (const Level& lv : f.caustic.levels)
    vecGrid(lv, "caustic_L" + std::to_string(lv.level), [&](size_t v) { return lv.radianceAt(v); });

  openvdb::MetaMap meta;
  // The caller's keys go under "voxcone:" so they never clash with the typed keys below.
  if (metadata.is_object())
    for (auto it = metadata.begin(); it != metadata.end(); ++it)
      meta.insertMeta("voxcone:" + it.key(),
                      openvdb::StringMetadata(it->is_string() ? it->get<std::string>() : it->dump()));
  meta.insertMeta("level", openvdb::Int32Metadata(f.settings.level));
  meta.insertMeta("coarsest_level", openvdb::Int32Metadata(f.settings.coarsestLevel));
  meta.insertMeta("caustic_level", openvdb::Int32Metadata(f.settings.causticLevel));
  meta.insertMeta("voxel_size", openvdb::DoubleMetadata(f.voxelSize(f.settings.level)));
  meta.insertMeta("global_photons", openvdb::Int64Metadata(int64_t(f.globalPhotons)));
  meta.insertMeta("caustic_photons", openvdb::Int64Metadata(int64_t(f.causticPhotons)));

  writeFileAtomic(path, [&](const std::string& tmpPath) {
    try {
      openvdb::io::File file(tmpPath);
      file.write(grids, meta);
      file.close();
    } catch (const openvdb::Exception& e) {
      throw Error(path + ": cannot write OpenVDB file: " + e.what());
    }
  });
}

}  // namespace voxcone
