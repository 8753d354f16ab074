/// \file voxel_field.cpp
/// The sparse voxel field: per level, one OpenVDB topology tree whose active values index a
/// table of superbricks, and per-voxel attributes stored compactly as structure-of-arrays. This
/// is the only translation unit of the library that includes OpenVDB (its headers are slow to
/// compile).
///
/// Layout of one level (why not OpenVDB value grids or a uint32 index per voxel in 4^3 leaves):
/// a flat wall leaves most of a dense leaf empty, so a dense index leaf costs ~19 bytes per active
/// voxel on the Cornell walls, more than all the attributes together. Instead voxels are grouped
/// in 4^3 bricks and bricks in 4^3 superbricks (16^3 voxels): the OpenVDB tree (Tree4<uint32_t,
/// 4, 3, 2>, leaves of 4^3 superbricks = 64^3 voxels) maps a superbrick coordinate to its index;
/// a superbrick holds a 64-bit mask of its bricks and the index of its first brick, a brick a
/// 64-bit mask of its voxels and the index of its first voxel, and voxel (i, j, k) is
///   brick = superBase[s] + popcount(superMask[s] & ((1 << bit(i>>2, j>>2, k>>2)) - 1))
///   voxel = brickBase[b] + popcount(brickMask[b] & ((1 << bit(i, j, k)) - 1)),
///   bit(i, j, k) = (i&3)<<4 | (j&3)<<2 | (k&3)
/// (the NanoVDB "index grid" idea, twice). Levels up to 8 keep a flat brick table instead of
/// the tree probe. Topology: 12 bytes per brick plus the superbricks, 0.9 bytes per voxel on
/// the dragon at level 10 (the tree of 4^3 brick leaves took 2.2).
///
/// Attributes per voxel (compact encodings, decoded by the accessors below):
///   coverage  half    finest level: surface area in the voxel / voxelSize^2 (may exceed 1);
///                     coarser levels: opacity (mean child opacity). Opacity = min(1, coverage).
///   normal    uint16  octahedral unit vector, 2 x 8 bit (Cigolle et al. 2014, "A Survey of
///                     Efficient Representations for Independent Unit Vectors"; < 1 degree
///                     error), stored renormalized (the opacity-weighted sum's length is not kept)
///   axes      3 x uint8 mips only: opacity-weighted mean |normal| per axis
/// and per brick, only for the bricks that need them (SparseBricks: 4 bytes per brick each):
///   radiance  uint32  front and back side, RGB9E5 shared exponent (EXT_texture_shared_exponent):
///                     9-bit mantissas, relative error <= 2^-10 on the largest channel, range
///                     [0, 65408] W/(sr m^2); bricks where some voxel's side is lit
///   diffuse   uint8   finest level: the diffuse fraction of the surface, bricks not wholly diffuse
/// No albedo: photons carry the albedo they landed on and inject reflected power.
/// Cornell-dragon at level 10 (4.7 M voxels, 6.3 M with the mips), 10k photons: 49.1 MB (with
/// dense two-sided radiance, albedo and 4^3 brick leaves it took 113.4 MB; 1M photons light
/// every voxel: 69.2 MB).

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
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <cmath>
#include <functional>
#include <mutex>
#include <optional>

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

constexpr double kPiD = 3.14159265358979323846;

/// What a cone lookup reads of one voxel, decoded once (Level::coneTable).
struct ConeVoxel {
  Vec3 projected;  ///< opacity times the axis fractions (|normal| per axis at the finest level)
  Vec3 side;       ///< the normal's direction (not normalized): which side a viewer sees
  Vec3 front, back;///< radiance of the side the normal points to, and of the other
};
static_assert(sizeof(ConeVoxel) == 48, "ConeVoxel is 12 floats");

/// Per-brick values stored only for the bricks that need them (most bricks do not: a closed
/// surface's back side is never lit, most surfaces are wholly diffuse): base[b] is the index of
/// brick b's first voxel in `values` (its voxels in rank order), or kNone; with no such brick
/// at all, `base` is empty too.
template <typename T> struct SparseBricks {
  static constexpr uint32_t kNone = ~uint32_t(0);
  std::vector<uint32_t> base;
  std::vector<T> values;
  T get(uint32_t brick, uint32_t rank, T fallback) const {
    if (brick >= base.size() || base[brick] == kNone) return fallback;
    return values[size_t(base[brick]) + rank];
  }
  bool stored(uint32_t brick) const { return brick < base.size() && base[brick] != kNone; }
  uint64_t bytes() const { return base.capacity() * sizeof(uint32_t) + values.capacity() * sizeof(T); }
  void shrink() {
    if (values.empty()) std::vector<uint32_t>().swap(base);
    base.shrink_to_fit();
    values.shrink_to_fit();
  }
};

/// Where a voxel's attributes are: its index in the dense arrays, its brick and its rank there.
struct VoxelRef {
  size_t index;
  uint32_t brick;
  uint32_t rank;
};

/// Code of a wholly diffuse voxel (Level::diffuse), the one not stored.
constexpr uint8_t kAllDiffuse = 255;

/// One level of a field: a two-level topology plus compact attributes.
struct Level {
  int level = 0;
  double voxelSize = 0.0;
  uint32_t resolution = 0;
  float invVoxelSize = 0.0f;            ///< 1 / voxelSize, for the float cone lookups
  float voxelSizeF = 0.0f;              ///< voxelSize in float
  std::unique_ptr<IndexTree> tree;      ///< superbrick coordinate -> superbrick index
  std::vector<uint64_t> superMask;      ///< occupied bricks of the superbrick
  std::vector<uint32_t> superBase;      ///< index of the superbrick's first brick
  std::vector<uint64_t> brickMask;      ///< occupied voxels of the brick
  std::vector<uint32_t> brickBase;      ///< index of the brick's first voxel
  /// Levels up to kDenseBrickLevel: brick coordinate -> brick index (or -1) in a flat array of
  /// (resolution / 4)^3 entries (1 MB at level 8), so lookups need no tree probe; empty above.
  std::vector<int32_t> denseBricks;
  std::vector<Half> coverage;
  std::vector<uint16_t> normal;
  /// Finest level: the diffuse fraction of the voxel's surface (unorm8), stored for the bricks
  /// holding a voxel not wholly diffuse (kAllDiffuse elsewhere). Injection weighs by it; the
  /// surfaces' albedo is not stored: photons carry the reflectance of the surface they landed
  /// on (Photon::albedo), so the field holds reflected light only.
  SparseBricks<uint8_t> diffuse;
  /// Surfaces are two-sided and each side keeps its own light (a panel lit from above stays
  /// dark below): RGB9E5 radiance of the front (side 0, the side the voxel's normal points to)
  /// and of the back (side 1), each stored for the bricks where some voxel's side is lit (the
  /// default 10k photons light a tenth of the dragon's level-10 voxels; a closed surface's back
  /// is never lit). Coarser levels: opacity-weighted means of the children's sides, after
  /// turning each child to agree with the parent's normal.
  SparseBricks<uint32_t> radiance[2];
  bool lit = false;                     ///< photons were injected (radiance holds their light)
  /// Mips only: opacity-weighted mean of |normal| per axis, 3 unorm8 per voxel (the finest
  /// level takes |normal| of its one mean normal).
  std::vector<uint8_t> axisFraction;
  /// Levels up to kConeTableLevel, once their radiance is final (buildConeTable): each voxel's
  /// cone-lookup attributes decoded, so a lookup's corner is one 48-byte read instead of a half,
  /// three unorm8 (or a normalized octahedral normal), another normal and an RGB9E5 decode.
  std::vector<ConeVoxel> coneTable;
  double buildSeconds = 0.0;

  size_t size() const { return coverage.size(); }

  /// Voxel (i, j, k), or false when inactive or outside.
  bool find(int64_t i, int64_t j, int64_t k, IndexAccessor& acc, VoxelRef& out) const {
    if (i < 0 || j < 0 || k < 0 || i >= resolution || j >= resolution || k >= resolution) return false;
    const int64_t brick = brickAt(int32_t(i >> 2), int32_t(j >> 2), int32_t(k >> 2), acc);
    if (brick < 0) return false;
    return voxelIn(uint32_t(brick), uint32_t(i), uint32_t(j), uint32_t(k), out);
  }
  /// Voxel (i, j, k) of brick `b` (which holds it), or false when inactive.
  bool voxelIn(uint32_t b, uint32_t i, uint32_t j, uint32_t k, VoxelRef& out) const {
    const uint32_t bit = voxel::brickBit(i, j, k);
    const uint64_t mask = brickMask[b];
    if (!((mask >> bit) & 1u)) return false;
    out.brick = b;
    out.rank = uint32_t(__builtin_popcountll(mask & ((uint64_t(1) << bit) - 1)));
    out.index = size_t(brickBase[b]) + out.rank;
    return true;
  }

  /// Index of brick (bi, bj, bk) (inside the level), or -1 when it has no voxel: from the flat
  /// table where there is one, else a probe of the tree for its superbrick and the rank of the
  /// brick's bit in the superbrick's mask.
  int64_t brickAt(int32_t bi, int32_t bj, int32_t bk, IndexAccessor& acc) const {
    if (!denseBricks.empty()) {
      const size_t side = resolution >> 2;
      return denseBricks[(size_t(bk) * side + size_t(bj)) * side + size_t(bi)];
    }
    uint32_t s = 0;
    if (!acc.probeValue(openvdb::Coord(bi >> 2, bj >> 2, bk >> 2), s)) return -1;
    const uint32_t bit = voxel::brickBit(uint32_t(bi), uint32_t(bj), uint32_t(bk));
    const uint64_t mask = superMask[s];
    if (!((mask >> bit) & 1u)) return -1;
    return int64_t(superBase[s]) + __builtin_popcountll(mask & ((uint64_t(1) << bit) - 1));
  }

  float opacity(size_t v) const { return std::min(1.0f, float(coverage[v])); }
  float diffuseAt(const VoxelRef& r) const { return decodeUnorm8(diffuse.get(r.brick, r.rank, kAllDiffuse)); }
  Vec3 frontAt(const VoxelRef& r) const { return decodeRgb9e5(radiance[0].get(r.brick, r.rank, 0u)); }
  Vec3 backAt(const VoxelRef& r) const { return decodeRgb9e5(radiance[1].get(r.brick, r.rank, 0u)); }
  /// Both sides' radiance summed.
  Vec3 radianceAt(const VoxelRef& r) const { return frontAt(r) + backAt(r); }
  Vec3 normalAt(size_t v) const { return decodeNormal(normal[v]); }
  Vec3 axisFractionAt(size_t v) const {
    if (axisFraction.empty()) return glm::abs(normalAt(v));
    return Vec3(decodeUnorm8(axisFraction[3 * v]), decodeUnorm8(axisFraction[3 * v + 1]),
                decodeUnorm8(axisFraction[3 * v + 2]));
  }

  /// Visit the voxels of superbrick `s` at superbrick coordinate (si, sj, sk): f(ref, i, j, k),
  /// in key order.
  template <typename F> void forEachVoxelOf(uint32_t s, uint32_t si, uint32_t sj, uint32_t sk, F&& f) const {
    forEachBrickOf(s, si, sj, sk, [&](uint32_t b, uint32_t bi, uint32_t bj, uint32_t bk) {
      uint64_t mask = brickMask[b];
      VoxelRef r{brickBase[b], b, 0};
      while (mask) {
        const uint32_t bit = uint32_t(__builtin_ctzll(mask));
        mask &= mask - 1;
        f(r, (bi << 2) | (bit >> 4), (bj << 2) | ((bit >> 2) & 3u), (bk << 2) | (bit & 3u));
        ++r.index;
        ++r.rank;
      }
    });
  }
  /// Visit the bricks of superbrick `s` at (si, sj, sk): f(brick index, bi, bj, bk), in key order.
  template <typename F> void forEachBrickOf(uint32_t s, uint32_t si, uint32_t sj, uint32_t sk, F&& f) const {
    uint64_t bricks = superMask[s];
    for (uint32_t b = superBase[s]; bricks; ++b) {
      const uint32_t bb = uint32_t(__builtin_ctzll(bricks));
      bricks &= bricks - 1;
      f(b, (si << 2) | (bb >> 4), (sj << 2) | ((bb >> 2) & 3u), (sk << 2) | (bb & 3u));
    }
  }
  /// Visit every voxel: f(ref, i, j, k), superbricks in tree order (callers sort when they need
  /// an order). The coordinates come from the tree, so no per-voxel key is stored.
  template <typename F> void forEachVoxel(F&& f) const {
    for (auto it = tree->cbeginValueOn(); it; ++it) {
      const openvdb::Coord c = it.getCoord();
      forEachVoxelOf(*it, uint32_t(c.x()), uint32_t(c.y()), uint32_t(c.z()), f);
    }
  }

  /// Voxel r's cone-lookup attributes, decoded (coneTable's entry where there is one).
  ConeVoxel coneVoxel(const VoxelRef& r) const {
    if (!coneTable.empty()) return coneTable[r.index];
    ConeVoxel c;
    c.projected = opacity(r.index) * axisFractionAt(r.index);
    c.side = decodeNormalDirection(normal[r.index]);
    c.front = frontAt(r);
    c.back = backAt(r);
    return c;
  }
  /// Decode every voxel's cone-lookup attributes into coneTable.
  void buildConeTable() {
    coneTable.clear();
    std::vector<ConeVoxel> table(size());
    forEachVoxel([&](const VoxelRef& r, uint32_t, uint32_t, uint32_t) { table[r.index] = coneVoxel(r); });
    coneTable = std::move(table);
  }

  uint64_t topologyBytes() const {
    return (tree ? tree->memUsage() : 0) + (superMask.capacity() + brickMask.capacity()) * sizeof(uint64_t) +
           (superBase.capacity() + brickBase.capacity()) * sizeof(uint32_t) + denseBricks.capacity() * sizeof(int32_t);
  }
};

/// Levels that keep a flat brick table (Level::denseBricks): 4 bytes per brick of the whole cube,
/// 1 MB at level 8; finer levels probe the tree.
constexpr int kDenseBrickLevel = 8;
/// Levels that keep decoded cone-lookup attributes (Level::coneTable, 48 bytes per voxel: 1.2 MB
/// for cornell-dragon's 25k voxels at level 6, 15 MB at level 8, so not there). Measured on
/// cornell-box at level 6: cone gathers 21% faster, the same image to 4 digits of PSNR.
constexpr int kConeTableLevel = 7;

/// The error the compact encodings add, per attribute (VoxelSettings::measureQuantization):
/// the largest and the mean over the voxels encoded.
struct QuantizationError {
  double maxError = 0.0, sum = 0.0;
  uint64_t count = 0;
  void add(double e) {
    maxError = std::max(maxError, e);
    sum += e;
    ++count;
  }
  nlohmann::json json() const { return {{"max", maxError}, {"mean", count ? sum / double(count) : 0.0}, {"voxels", count}}; }
};
struct FieldQuantization {
  QuantizationError coverage;  ///< relative (half)
  QuantizationError normal;    ///< degrees (octahedral 2 x 8 bit)
  QuantizationError radiance;  ///< relative to the largest channel (RGB9E5), lit sides only
  QuantizationError axes;      ///< absolute (unorm8)
  QuantizationError diffuse;   ///< absolute (unorm8)
  /// The error of encoding x as RGB9E5, relative to its largest channel.
  void addRadiance(const Vec3& x, uint32_t code) {
    const float m = maxComponent(x);
    if (m > 0.0f) radiance.add(double(maxComponent(glm::abs(decodeRgb9e5(code) - x))) / double(m));
  }
};

/// Builds a level from runs of full-precision voxels in key order (VoxelSink), encoding each
/// run as it comes: the level never exists in full precision. With `quant`, the error of every
/// encoding is measured into it.
class LevelBuilder {
public:
  LevelBuilder(int level, double voxelSize, FieldQuantization* quant = nullptr) : m_quant(quant) {
    m_out.level = level;
    m_out.voxelSize = voxelSize;
    m_out.invVoxelSize = float(1.0 / voxelSize);
    m_out.voxelSizeF = float(voxelSize);
    m_out.resolution = uint32_t(1) << level;
    m_out.tree = std::make_unique<IndexTree>(uint32_t(0));
    m_acc = std::make_unique<openvdb::tree::ValueAccessor<IndexTree>>(*m_out.tree);
  }

  void append(const VoxelArrays& a) {
    Level& o = m_out;
    const bool lit = !a.radiance.empty();
    o.lit = o.lit || lit;
    for (size_t v = 0; v < a.size(); ++v) {
      const uint64_t key = a.keys[v];
      if ((key >> 6) != m_lastBrick) {
        flushBrick();
        if ((key >> 12) != m_lastSuper) {
          uint32_t si, sj, sk;
          voxel::unpackBrick(key >> 12, si, sj, sk);
          m_acc->setValue(openvdb::Coord(int32_t(si), int32_t(sj), int32_t(sk)), uint32_t(o.superMask.size()));
          o.superMask.push_back(0);
          o.superBase.push_back(uint32_t(o.brickMask.size()));
          m_lastSuper = key >> 12;
        }
        o.superMask.back() |= uint64_t(1) << ((key >> 6) & 63u);
        o.brickMask.push_back(0);
        o.brickBase.push_back(uint32_t(o.coverage.size()));
        m_lastBrick = key >> 6;
      }
      o.brickMask.back() |= uint64_t(1) << (key & 63u);
      o.coverage.push_back(Half(a.coverage[v]));
      o.normal.push_back(encodeNormal(a.normal[v]));
      if (!a.diffuse.empty()) m_diffuse.push_back(encodeUnorm8(a.diffuse[v]));
      if (lit) {
        m_radiance[0].push_back(encodeRgb9e5(a.radiance[v]));
        m_radiance[1].push_back(encodeRgb9e5(a.radianceBack[v]));
      }
      if (!a.axisFraction.empty())
        for (int c = 0; c < 3; ++c) o.axisFraction.push_back(encodeUnorm8(a.axisFraction[v][c]));
      if (m_quant) measure(a, v);
    }
  }

  Level finish() {
    flushBrick();
    Level& o = m_out;
    for (auto* v : {&o.superMask, &o.brickMask}) v->shrink_to_fit();
    for (auto* v : {&o.superBase, &o.brickBase}) v->shrink_to_fit();
    o.coverage.shrink_to_fit();
    o.normal.shrink_to_fit();
    o.axisFraction.shrink_to_fit();
    o.diffuse.shrink();
    for (SparseBricks<uint32_t>& side : o.radiance) side.shrink();
    if (o.level <= kDenseBrickLevel) {
      const size_t side = o.resolution >> 2;
      o.denseBricks.assign(std::max<size_t>(1, side * side * side), -1);
      for (auto it = o.tree->cbeginValueOn(); it; ++it) {
        const openvdb::Coord c = it.getCoord();
        o.forEachBrickOf(*it, uint32_t(c.x()), uint32_t(c.y()), uint32_t(c.z()),
                         [&](uint32_t b, uint32_t bi, uint32_t bj, uint32_t bk) {
                           o.denseBricks[(size_t(bk) * side + bj) * side + bi] = int32_t(b);
                         });
      }
    }
    m_acc.reset();
    return std::move(m_out);
  }

private:
  /// The error of voxel v's encodings (the ones append just stored).
  void measure(const VoxelArrays& a, size_t v) {
    const Level& o = m_out;
    if (a.coverage[v] > 0.0f)
      m_quant->coverage.add(std::abs(double(float(o.coverage.back())) - double(a.coverage[v])) / double(a.coverage[v]));
    const float cosine = std::clamp(glm::dot(decodeNormal(o.normal.back()), a.normal[v]), -1.0f, 1.0f);
    m_quant->normal.add(double(std::acos(cosine)) * 180.0 / kPiD);
    if (!a.diffuse.empty()) m_quant->diffuse.add(std::abs(double(decodeUnorm8(m_diffuse.back())) - double(a.diffuse[v])));
    if (!a.radiance.empty()) {
      m_quant->addRadiance(a.radiance[v], m_radiance[0].back());
      m_quant->addRadiance(a.radianceBack[v], m_radiance[1].back());
    }
    if (!a.axisFraction.empty())
      for (int c = 0; c < 3; ++c)
        m_quant->axes.add(std::abs(double(decodeUnorm8(o.axisFraction[o.axisFraction.size() - 3 + size_t(c)])) -
                                   double(a.axisFraction[v][c])));
  }

  FieldQuantization* m_quant = nullptr;

  /// The brick just completed: its diffuse fractions and each side's radiance are kept only
  /// when some voxel of it needs them (SparseBricks).
  void flushBrick() {
    if (m_lastBrick == ~uint64_t(0)) return;
    auto keep = [&](auto& sparse, auto& pending, auto none) {
      const bool needed = std::any_of(pending.begin(), pending.end(), [&](auto c) { return c != none; });
      if (needed) {
        sparse.base.resize(m_out.brickMask.size() - 1, sparse.kNone);
        sparse.base.push_back(uint32_t(sparse.values.size()));
        sparse.values.insert(sparse.values.end(), pending.begin(), pending.end());
      }
      pending.clear();
    };
    keep(m_out.diffuse, m_diffuse, kAllDiffuse);
    for (int side = 0; side < 2; ++side) keep(m_out.radiance[side], m_radiance[side], uint32_t(0));
  }

  Level m_out;
  std::unique_ptr<openvdb::tree::ValueAccessor<IndexTree>> m_acc;
  uint64_t m_lastBrick = ~uint64_t(0), m_lastSuper = ~uint64_t(0);
  std::vector<uint8_t> m_diffuse;   ///< the current brick's
  std::vector<uint32_t> m_radiance[2];  ///< the current brick's
};

/// 2x2x2 box restriction of `child` (parent (i, j, k) = child (i, j, k) >> 1), or the binomial
/// over 4x4x4 (MipFilter::Gaussian): opacity = weighted sum of child opacities; no diffuse
/// fraction (only injection reads it). Surfaces are two-sided, so each child is first turned
/// to agree with the most opaque child's normal (its front and back swapped when turned);
/// normal = opacity-weighted sum of the turned normals, renormalized; front and back radiance =
/// opacity-weighted means (sum(opacity * radiance) * voxel volume is preserved before storage).
/// For cones: axisFraction = opacity-weighted mean |normal| per axis.
/// The weight a child voxel gives one parent, per axis, in eighths: box 4 (its own parent
/// only, 4/8 per axis = 1/8 in 3D); Gaussian 3 to its own parent and 1 to the parent beside it
/// on its side (the binomial [1 3 3 1] / 8 over the 4 children nearest the parent's centre).
/// Either way a child's weights sum to 1/8 and a parent's to 1: coverage and flux are
/// conserved, and a plane stays one crossing (VoxelSample::projected) at every level.
struct ChildShare {
  uint64_t parent;
  VoxelRef child;
  float weight;
  bool operator<(const ChildShare& o) const {
    return parent != o.parent ? parent < o.parent : child.index < o.child.index;
  }
};

/// The shares of `child`'s voxel (i, j, k) in the parents of superbrick `ps` (packBrick), added
/// to `shares`.
void addShares(const VoxelRef& r, uint32_t i, uint32_t j, uint32_t k, uint32_t parentRes, MipFilter filter,
               uint64_t ps, std::vector<ChildShare>& shares) {
  const uint32_t c[3] = {i, j, k};
  if (filter == MipFilter::Box) {
    const uint64_t key = voxel::packKey(i >> 1, j >> 1, k >> 1);
    if ((key >> 12) == ps) shares.push_back({key, r, 0.125f});
    return;
  }
  uint32_t own[3], other[3];
  for (int a = 0; a < 3; ++a) {
    own[a] = c[a] >> 1;
    // An even child lies on its parent's low side, next to the parent below. At the
    // field's faces the neighbour does not exist: its share goes to the own parent.
    const int64_t n = (c[a] & 1u) ? int64_t(own[a]) + 1 : int64_t(own[a]) - 1;
    other[a] = n < 0 || n >= int64_t(parentRes) ? own[a] : uint32_t(n);
  }
  const size_t first = shares.size();
  for (int corner = 0; corner < 8; ++corner) {
    uint32_t q[3];
    float w = 1.0f;
    for (int a = 0; a < 3; ++a) {
      const bool side = (corner >> a) & 1;
      q[a] = side ? other[a] : own[a];
      w *= side ? 0.125f : 0.375f;
    }
    const uint64_t key = voxel::packKey(q[0], q[1], q[2]);
    if ((key >> 12) != ps) continue;
    // A child whose neighbour was folded back names its own parent twice: merge those.
    bool merged = false;
    for (size_t s = first; s < shares.size() && !merged; ++s)
      if (shares[s].parent == key) {
        shares[s].weight += w;
        merged = true;
      }
    if (!merged) shares.push_back({key, r, w});
  }
}

/// The parents of superbrick `ps` from sorted `shares` (one parent's run after another), appended to `out`.
void reduceShares(const Level& child, const std::vector<ChildShare>& shares, VoxelArrays& out) {
  const bool lit = child.lit;
  for (size_t a = 0; a < shares.size();) {
    size_t end = a;
    size_t ref = a;  // the child that weighs most: the others turn to agree with it
    for (; end < shares.size() && shares[end].parent == shares[a].parent; ++end)
      if (shares[end].weight * child.opacity(shares[end].child.index) >
          shares[ref].weight * child.opacity(shares[ref].child.index))
        ref = end;
    const Vec3 refNormal = child.normalAt(shares[ref].child.index);
    double opSum = 0.0;
    DVec3 front(0.0), back(0.0), nrm(0.0), axes(0.0);
    for (size_t b = a; b < end; ++b) {
      const VoxelRef& c = shares[b].child;
      const double op = double(shares[b].weight) * child.opacity(c.index);
      const Vec3 n = child.normalAt(c.index);
      const bool turned = glm::dot(n, refNormal) < 0.0f;
      opSum += op;
      nrm += op * DVec3(turned ? -n : n);
      axes += op * DVec3(child.axisFractionAt(c.index));
      if (lit) {
        const DVec3 f = DVec3(child.frontAt(c)), k = DVec3(child.backAt(c));
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
}

/// One coarser level from `child` (VoxelField::buildMips), a parent superbrick at a time: its
/// children lie in the 2^3 child superbricks below it (box) or the 4^3 around those (Gaussian);
/// each parent's shares are summed in child index order, so the level is the same at any
/// thread count. Parent superbricks go in parallel batches appended in key order.
Level restrictLevel(const Level& child, MipFilter filter, FieldQuantization* quant) {
  const uint32_t parentRes = std::max(1u, child.resolution >> 1);
  const int32_t childSupers = int32_t(std::max(1u, child.resolution >> voxel::kSuperLog2));
  // The parent superbricks with a child: those above each child superbrick (and beside, for
  // the Gaussian's reach across a superbrick's face), in key order.
  std::vector<uint64_t> parents;
  const int reach = filter == MipFilter::Box ? 0 : 1;
  const int32_t parentSupers = std::max(1, int32_t((parentRes + (1u << voxel::kSuperLog2) - 1) >> voxel::kSuperLog2));
  for (auto it = child.tree->cbeginValueOn(); it; ++it) {
    const openvdb::Coord c = it.getCoord();
    for (int dx = -reach; dx <= reach; ++dx)
      for (int dy = -reach; dy <= reach; ++dy)
        for (int dz = -reach; dz <= reach; ++dz) {
          const int32_t p[3] = {(c.x() >> 1) + dx, (c.y() >> 1) + dy, (c.z() >> 1) + dz};
          if (p[0] < 0 || p[1] < 0 || p[2] < 0 || p[0] >= parentSupers || p[1] >= parentSupers || p[2] >= parentSupers)
            continue;
          parents.push_back(voxel::packBrick(uint32_t(p[0]), uint32_t(p[1]), uint32_t(p[2])));
        }
  }
  tbb::parallel_sort(parents.begin(), parents.end());
  parents.erase(std::unique(parents.begin(), parents.end()), parents.end());

  LevelBuilder builder(child.level - 1, child.voxelSize * 2.0, quant);
  constexpr size_t kBatch = 256;
  std::vector<VoxelArrays> batch(kBatch);
  for (size_t first = 0; first < parents.size(); first += kBatch) {
    const size_t count = std::min(kBatch, parents.size() - first);
    tbb::parallel_for(size_t(0), count, [&](size_t n) {
      const uint64_t ps = parents[first + n];
      uint32_t p[3];
      voxel::unpackBrick(ps, p[0], p[1], p[2]);
      IndexAccessor acc(*child.tree);
      std::vector<ChildShare> shares;
      for (int32_t cx = 2 * int32_t(p[0]) - reach; cx <= 2 * int32_t(p[0]) + 1 + reach; ++cx)
        for (int32_t cy = 2 * int32_t(p[1]) - reach; cy <= 2 * int32_t(p[1]) + 1 + reach; ++cy)
          for (int32_t cz = 2 * int32_t(p[2]) - reach; cz <= 2 * int32_t(p[2]) + 1 + reach; ++cz) {
            if (cx < 0 || cy < 0 || cz < 0 || cx >= childSupers || cy >= childSupers || cz >= childSupers) continue;
            uint32_t s = 0;
            if (!acc.probeValue(openvdb::Coord(cx, cy, cz), s)) continue;
            child.forEachVoxelOf(s, uint32_t(cx), uint32_t(cy), uint32_t(cz),
                                 [&](const VoxelRef& r, uint32_t i, uint32_t j, uint32_t k) {
                                   addShares(r, i, j, k, parentRes, filter, ps, shares);
                                 });
          }
      std::sort(shares.begin(), shares.end());
      batch[n].clear();
      reduceShares(child, shares, batch[n]);
    });
    for (size_t n = 0; n < count; ++n) builder.append(batch[n]);
  }
  return builder.finish();
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
    VoxelRef r;
    if (!lv.find(int64_t(base.x) + dx, int64_t(base.y) + dy, int64_t(base.z) + dz, access, r)) continue;
    const double wo = w * lv.opacity(r.index);
    acc.weight += wo;
    acc.opacity += wo;
    acc.radiance += wo * DVec3(lv.radianceAt(r));
    acc.normal += wo * DVec3(lv.normalAt(r.index));
    acc.projected += wo * DVec3(lv.axisFractionAt(r.index));
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
    VoxelRef r;
    if (!lv.voxelIn(uint32_t(b), uint32_t(i), uint32_t(j), uint32_t(k), r)) continue;
    // Projected area along the cone's direction, and the radiance of the side the apex sees
    // (the direction from the apex, not the axis: a lookup's reach takes in surfaces beside
    // the axis, and a ray from the apex reaches them from their apex side).
    const Vec3 centre = (Vec3(float(i), float(j), float(k)) + Vec3(0.5f)) * lv.voxelSizeF;
    const ConeVoxel cv = lv.coneVoxel(r);
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
  uint64_t sceneHash = 0;     ///< fieldSceneHash of the scene voxelized
  FieldQuantization quant;    ///< the main grid's encoding errors (settings.measureQuantization)

  FieldQuantization* quantPtr() { return settings.measureQuantization ? &quant : nullptr; }

  double voxelSize(int level) const { return extent / double(uint64_t(1) << level); }
  void inject(Grid& grid, const PhotonList& photons, Progress* progress, DVec3& injectedOut);
};

namespace {

/// Reflected flux (photon power times the albedo it landed on) per voxel and side (front: the
/// side the voxel's normal points to), only for the bricks some photon reached on that side (a
/// few thousand photons reach a fraction of a fine level's bricks).
struct SidedFlux {
  SparseBricks<Vec3> side[2];
};

/// The footprint spreads a photon over the surface it landed on: a voxel whose mean normal
/// turns more than 60 degrees from the photon's belongs to another surface across a crease (a
/// wall beside a lit floor), not to this one; a corner voxel's 45 degrees still counts.
constexpr float kSameSurfaceCos = 0.5f;

/// Splat `photons` into `lv` (see VoxelField::inject); returns the reflected flux per voxel and
/// side, and adds the power that landed to `injected`, that found no voxel to `dropped`.
SidedFlux splatPhotons(const Level& lv, const DVec3& origin, const PhotonList& photons, float sigmaVoxels,
                       DVec3& injected, DVec3& dropped, Progress* progress) {
  SidedFlux flux;
  for (SparseBricks<Vec3>& f : flux.side) f.base.assign(lv.brickMask.size(), SparseBricks<Vec3>::kNone);
  const double radius = 3.0 * double(sigmaVoxels);
  const double inv2s2 = 1.0 / (2.0 * double(sigmaVoxels) * sigmaVoxels);
  // Photons go in fixed blocks; a wave of blocks is splatted in parallel into per-block lists,
  // then added in block order, so the float sums are the same at any thread count.
  constexpr size_t kBlock = 2048, kWave = 64;
  const size_t blocks = (photons.size() + kBlock - 1) / kBlock;
  struct Splat {
    uint32_t brick;
    uint8_t rank;
    bool back;
    Vec3 flux;
  };
  std::vector<std::vector<Splat>> lists(std::min(blocks, kWave));
  std::vector<DVec3> blockLanded(lists.size()), blockDropped(lists.size());
  for (size_t wave = 0; wave < blocks; wave += kWave) {
    if (progress && progress->cancelled()) throw CancelledError();
    const size_t waveBlocks = std::min(kWave, blocks - wave);
    tbb::parallel_for(size_t(0), waveBlocks, [&](size_t wb) {
      std::vector<Splat>& out = lists[wb];
      out.clear();
      blockLanded[wb] = blockDropped[wb] = DVec3(0.0);
      IndexAccessor access(*lv.tree);
      struct Candidate {
        VoxelRef voxel;
        float weight;
      };
      // Voxels whose (wound) normal faces the photon, and those facing away from it.
      std::vector<Candidate> cand[2];
      std::vector<double> gauss[3];
      const size_t begin = (wave + wb) * kBlock, end = std::min(photons.size(), begin + kBlock);
      for (size_t p = begin; p < end; ++p) {
        const Photon& ph = photons[p];
        const Vec3 reflected = ph.power * ph.albedo;
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
              VoxelRef r;
              if (!lv.find(i, j, k, access, r)) continue;
              // Only diffuse surface gathers light.
              const float diffuse = lv.diffuseAt(r);
              if (!(diffuse > 0.0f)) continue;
              // Voxels of another surface (kSameSurfaceCos) take none of the photon.
              const Vec3 n = decodeNormalDirection(lv.normal[r.index]);
              const float cosNormals = glm::dot(n, ph.normal);
              if (sqr(cosNormals) <= sqr(kSameSurfaceCos) * glm::dot(n, n)) continue;
              // Gaussian footprint times the diffuse surface area the voxel holds: a uniform
              // photon density then gives a uniform irradiance flux / area, where the plain
              // Gaussian would give a voxel clipped to a sliver of surface the flux of a full
              // voxel (and radiance up to 1 / sliver area).
              const double g = gauss[0][size_t(i - lo[0])] * gauss[1][size_t(j - lo[1])] * gauss[2][size_t(k - lo[2])];
              const double w = g * double(lv.coverage[r.index]) * double(diffuse);
              const int back = cosNormals < 0.0f;
              cand[back].push_back({r, float(w)});
              wsum[back] += w;
            }
        // The photon lands on the side it arrived on: the front of the voxels that face it (a
        // closed object's far face, in the next voxel layer, stays dark inside), or, where none
        // does, the back of those facing away (an open panel lit from behind its winding).
        // Normalized over the chosen voxels: the photon's power is conserved.
        const int side = wsum[0] > 0.0 ? 0 : 1;
        if (wsum[side] > 0.0) {
          for (const Candidate& c : cand[side])
            out.push_back({c.voxel.brick, uint8_t(c.voxel.rank), side == 1, reflected * float(double(c.weight) / wsum[side])});
          blockLanded[wb] += DVec3(ph.power);
          continue;
        }
        VoxelRef r;
        if (lv.find(int64_t(std::floor(q.x)), int64_t(std::floor(q.y)), int64_t(std::floor(q.z)), access, r)) {
          out.push_back({r.brick, uint8_t(r.rank),
                         glm::dot(decodeNormalDirection(lv.normal[r.index]), ph.normal) < 0.0f, reflected});
          blockLanded[wb] += DVec3(ph.power);
        } else {
          blockDropped[wb] += DVec3(ph.power);
        }
      }
    });
    for (size_t wb = 0; wb < waveBlocks; ++wb) {
      for (const Splat& s : lists[wb]) {
        SparseBricks<Vec3>& f = flux.side[s.back];
        uint32_t& base = f.base[s.brick];
        if (base == SparseBricks<Vec3>::kNone) {
          base = uint32_t(f.values.size());
          f.values.resize(f.values.size() + size_t(__builtin_popcountll(lv.brickMask[s.brick])), Vec3(0.0f));
        }
        f.values[size_t(base) + s.rank] += s.flux;
      }
      injected += blockLanded[wb];
      dropped += blockDropped[wb];
    }
    if (progress) progress->advance(std::min(photons.size(), (wave + waveBlocks) * kBlock) - wave * kBlock);
  }
  return flux;
}

/// The voxels of `lv` with nonzero radiance, as a level of their own.
Level keepLit(const Level& lv) {
  struct Lit {
    uint64_t key;
    VoxelRef ref;
    bool operator<(const Lit& o) const { return key < o.key; }
  };
  std::vector<Lit> lit;
  lv.forEachVoxel([&](const VoxelRef& r, uint32_t i, uint32_t j, uint32_t k) {
    if (!isBlack(lv.radianceAt(r))) lit.push_back({voxel::packKey(i, j, k), r});
  });
  std::sort(lit.begin(), lit.end());
  VoxelArrays a;
  for (const Lit& l : lit) {
    a.keys.push_back(l.key);
    a.coverage.push_back(float(lv.coverage[l.ref.index]));
    a.normal.push_back(lv.normalAt(l.ref.index));
    a.diffuse.push_back(lv.diffuseAt(l.ref));
    a.radiance.push_back(lv.frontAt(l.ref));
    a.radianceBack.push_back(lv.backAt(l.ref));
  }
  LevelBuilder builder(lv.level, lv.voxelSize);
  builder.append(a);
  Level out = builder.finish();
  out.buildSeconds = lv.buildSeconds;
  return out;
}

}  // namespace

void VoxelField::Impl::inject(Grid& grid, const PhotonList& photons, Progress* progress, DVec3& injectedOut) {
  if (grid.empty()) return;
  Timer timer;
  Level& lv = grid.levels.front();
  injectedOut = DVec3(0.0);
  SidedFlux flux = splatPhotons(lv, origin, photons, settings.kernelSigmaVoxels, injectedOut, dropped, progress);
  // L = Phi_r / (pi A) per side, Phi_r the reflected flux (albedo times the power that landed),
  // A = coverage * voxelSize^2 the voxel's whole surface (each side of a two-sided surface has
  // all of it): the mean over the voxel's surface of the diffuse part's albedo / pi * E.
  const double voxelArea = lv.voxelSize * lv.voxelSize;
  const auto radianceOf = [&](const SparseBricks<Vec3>& f, uint32_t brick, uint32_t rank) {
    const double area = double(lv.coverage[size_t(lv.brickBase[brick]) + rank]) * voxelArea;
    return area > 0.0 ? Vec3(DVec3(f.values[size_t(f.base[brick]) + rank]) * (1.0 / (kPiD * area))) : Vec3(0.0f);
  };
  lv.coneTable.clear();  // stale until buildConeTable runs again
  // Each side in the flux's own sparse layout, the bricks no photon reached left out.
  for (int side = 0; side < 2; ++side) {
    SparseBricks<Vec3>& f = flux.side[side];
    SparseBricks<uint32_t>& out = lv.radiance[side];
    out = SparseBricks<uint32_t>();
    if (!f.values.empty()) {
      out.base = f.base;
      out.values.resize(f.values.size());
      tbb::parallel_for(uint32_t(0), uint32_t(lv.brickMask.size()), [&](uint32_t b) {
        if (f.base[b] == SparseBricks<Vec3>::kNone) return;
        const uint32_t n = uint32_t(__builtin_popcountll(lv.brickMask[b]));
        for (uint32_t r = 0; r < n; ++r) out.values[size_t(f.base[b]) + r] = encodeRgb9e5(radianceOf(f, b, r));
      });
    }
    if (FieldQuantization* q = &grid == &main ? quantPtr() : nullptr)
      for (uint32_t b = 0; b < lv.brickMask.size() && !f.values.empty(); ++b) {
        if (f.base[b] == SparseBricks<Vec3>::kNone) continue;
        for (uint32_t r = 0; r < uint32_t(__builtin_popcountll(lv.brickMask[b])); ++r)
          q->addRadiance(radianceOf(f, b, r), out.values[size_t(f.base[b]) + r]);
      }
    f = SparseBricks<Vec3>();
  }
  lv.lit = true;
  // Mips built before are stale: dropped, buildMips makes them anew (rebuilding them here too
  // built every mip twice per pass of a progressive render).
  grid.levels.resize(1);
  grid.injectSeconds = timer.seconds();
}

VoxelField::VoxelField() : m_impl(std::make_unique<Impl>()) {}
VoxelField::~VoxelField() = default;
VoxelField::VoxelField(VoxelField&&) noexcept = default;
VoxelField& VoxelField::operator=(VoxelField&&) noexcept = default;

namespace {
/// The cube a field of `scene` covers: its bounds' lower corner less the padding, its longest
/// side plus twice the padding.
void fieldCube(const Scene& scene, double padding, DVec3& origin, double& extent) {
  const Bounds3& sb = scene.bounds();
  const DVec3 diag = DVec3(sb.hi) - DVec3(sb.lo);
  const double side = std::max(diag.x, std::max(diag.y, diag.z));
  const double pad = padding * side;
  origin = DVec3(sb.lo) - DVec3(pad);
  // Pad by a relative 1e-6 so the max corner falls inside the last voxel, not on its far face.
  extent = (side + 2.0 * pad) * (1.0 + 1e-6);
}
}  // namespace

namespace {

/// The bytes a level of `voxels` voxels in `bricks` bricks takes (Level's layout, every voxel's
/// front lit, no back; the mips' axes and cone tables; the flat brick table up to level 8).
double levelBytes(int level, double voxels, double bricks, bool finest) {
  double bytes = voxels * (2.0 + 2.0 + 4.0)        // coverage, normal, front radiance
                 + bricks * (8.0 + 4.0 + 2 * 4.0)  // mask, base, the two sides' sparse bases
                 + bricks / 8.0 * 12.0;            // superbricks (a surface's fill a half of one's bricks)
  if (finest) bytes += bricks * 4.0;               // the diffuse fraction's sparse base
  else bytes += voxels * 3.0;                      // axes
  if (level <= kConeTableLevel) bytes += voxels * double(sizeof(ConeVoxel));
  if (level <= kDenseBrickLevel) bytes += std::pow(double(uint64_t(1) << level) / 4.0, 3.0) * 4.0;
  return bytes;
}

std::string megabytes(uint64_t bytes) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.0f MB", double(bytes) / 1e6);
  return buf;
}

}  // namespace

std::vector<FieldEstimate> VoxelField::estimate(const Scene& scene, const VoxelSettings& settings, bool quick,
                                                uint64_t budget) {
  DVec3 origin;
  double extent;
  fieldCube(scene, settings.padding, origin, extent);
  const int top = settings.level;
  // Per finest level m: its voxels V(m) and voxels per brick, from a count at level `probe`
  // (exact), growing by sqrt(voxels per brick) per level (4 on a surface: a brick of level
  // m + 2 is a voxel of level m).
  auto rowsFrom = [&](int probe, double voxels, double fill) {
    const double growth = std::sqrt(std::max(1.0, fill));
    std::vector<FieldEstimate> rows;
    for (int finest = settings.coarsestLevel; finest <= top; ++finest) {
      FieldEstimate e;
      e.level = finest;
      e.probeLevel = probe;
      double field = 0.0, finestVoxels = 0.0;
      for (int m = settings.coarsestLevel; m <= finest; ++m) {
        const double v = std::max(1.0, voxels * std::pow(growth, double(m - std::max(probe, 1))));
        if (m == finest) finestVoxels = v;
        field += levelBytes(m, v, std::max(1.0, v / std::max(1.0, fill)), m == finest);
      }
      e.voxels = uint64_t(finestVoxels);
      e.fieldBytes = uint64_t(field);
      // Held at once besides the field: one slab of voxelizeTriangles (48 bytes per overlap),
      // its work items (28 bytes per triangle, twice while they are cut into slabs), the
      // builder's arrays growing (coverage and normal copied as they double), injection's flux
      // (12 bytes per lit voxel).
      // A slab holds at most kRegionContributions overlaps, and about 3 per voxel (measured on
      // the dragon at level 10: 1.6 overlaps per voxel).
      const double slab = std::min(double(voxel::kRegionContributions), 3.0 * finestVoxels);
      const double transient = slab * 48.0 + 56.0 * double(scene.triangleCount()) + finestVoxels * (4.0 + 12.0);
      e.peakBytes = uint64_t(field + transient);
      rows.push_back(e);
    }
    return rows;
  };
  if (quick) {
    // The triangles' voxel boxes bound the finest level's voxels from above.
    const double bound = double(voxel::voxelBoxBound(scene, origin, extent / double(uint64_t(1) << top), uint32_t(1) << top));
    std::vector<FieldEstimate> rows = rowsFrom(top, bound, 16.0);
    for (FieldEstimate& r : rows) r.probeLevel = 0;
    if (rows.back().peakBytes <= budget) return rows;
  }
  const int probe = std::max(1, std::min(top - 2, 9));
  const double vs = extent / double(uint64_t(1) << probe);
  uint64_t voxels = 0, bricks = 0, lastBrick = ~uint64_t(0);
  voxel::voxelizeTriangles(scene, origin, vs, uint32_t(1) << probe, nullptr, [&](voxel::VoxelArrays& run) {
    voxels += run.size();
    for (uint64_t key : run.keys)
      if ((key >> 6) != lastBrick) {
        ++bricks;
        lastBrick = key >> 6;
      }
  });
  return rowsFrom(probe, double(voxels), double(voxels) / double(std::max<uint64_t>(1, bricks)));
}

namespace {
/// A hash (FNV-1a on words) of what a field's content depends on: geometry (positions, smooth normals,
/// triangles, their materials), the materials' optical values and the point lights; not the
/// camera or the render settings, so one field serves many views.
uint64_t fieldSceneHash(const Scene& scene) {
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
    const int32_t kinds[4] = {int32_t(m.type), int32_t(m.distribution), int32_t(m.twoSidedEmission), int32_t(m.twoSided)};
    bytes(kinds, sizeof kinds);
    floats({m.albedo.x, m.albedo.y, m.albedo.z, m.sigmaRad, m.specular.x, m.specular.y, m.specular.z, m.ior, m.eta.x,
            m.eta.y, m.eta.z, m.k.x, m.k.y, m.k.z, m.roughness, m.emission.x, m.emission.y, m.emission.z});
  }
  for (const PointLight& l : scene.pointLights)
    floats({l.position.x, l.position.y, l.position.z, l.intensity.x, l.intensity.y, l.intensity.z});
  return h;
}
}  // namespace

void VoxelField::checkScene(const Scene& scene, const std::string& what) const {
  const Impl& f = *m_impl;
  if (f.sceneHash != 0 && f.sceneHash != fieldSceneHash(scene))
    throw SettingsError(what + ": the field was built for another scene (its geometry, materials or lights differ)");
  DVec3 origin;
  double extent;
  fieldCube(scene, f.settings.padding, origin, extent);
  const double tol = 1e-9 * std::max(std::abs(extent), 1e-300);
  if (std::abs(extent - f.extent) > tol || glm::length(origin - f.origin) > tol)
    throw SettingsError(what + ": the field was voxelized for another scene (it covers a cube of side " +
                        std::to_string(f.extent) + " at (" + std::to_string(f.origin.x) + ", " + std::to_string(f.origin.y) +
                        ", " + std::to_string(f.origin.z) + "), this scene needs side " + std::to_string(extent) + ")");
}

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

  // The memory budget, before anything is allocated.
  const uint64_t budget = settings.memoryBudgetBytes == VoxelSettings::kAvailableMemory ? availableMemoryBytes()
                                                                                        : settings.memoryBudgetBytes;
  if (budget > 0 && budget != VoxelSettings::kNoBudget) {
    const std::vector<FieldEstimate> rows = estimate(scene, settings, true, budget);
    if (rows.back().peakBytes > budget) {
      std::string fits = "no level from " + std::to_string(settings.coarsestLevel) + " fits";
      for (auto it = rows.rbegin(); it != rows.rend(); ++it)
        if (it->peakBytes <= budget) {
          fits = "level " + std::to_string(it->level) + " would fit (about " + megabytes(it->peakBytes) + ")";
          break;
        }
      throw SettingsError("voxel level " + std::to_string(settings.level) + " needs about " +
                          megabytes(rows.back().peakBytes) + " (the field " + megabytes(rows.back().fieldBytes) +
                          "), more than the memory budget of " + megabytes(budget) +
                          (settings.memoryBudgetBytes == VoxelSettings::kAvailableMemory ? " (the available memory)" : "") +
                          "; " + fits);
    }
  }

  VoxelField field;
  Impl& f = *field.m_impl;
  f.settings = settings;
  fieldCube(scene, settings.padding, f.origin, f.extent);
  f.originF = Vec3(f.origin);
  f.sceneHash = fieldSceneHash(scene);
  if (!(f.extent > 0.0)) throw SettingsError("cannot voxelize a scene of zero extent");
  f.bounds = Bounds3(Vec3(f.origin), Vec3(f.origin + DVec3(f.extent)));

  auto build = [&](Grid& grid, int level, bool countArea, const std::vector<uint64_t>* onlyBricks) {
    Timer timer;
    const double vs = f.voxelSize(level);
    LevelBuilder builder(level, vs, countArea ? f.quantPtr() : nullptr);
    double area = 0.0;
    voxel::voxelizeTriangles(
        scene, f.origin, vs, uint32_t(1) << level, progress,
        [&](voxel::VoxelArrays& run) {
          if (countArea)
            for (float c : run.coverage) area += double(c);
          builder.append(run);
        },
        onlyBricks);
    if (countArea) f.surfaceArea = area * vs * vs;
    grid.levels.push_back(builder.finish());
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
      Level parent = restrictLevel(grid->levels.back(), f.settings.mipFilter, f.quantPtr());
      parent.buildSeconds = t.seconds();
      grid->levels.push_back(std::move(parent));
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
  VoxelRef r;
  if (!lv->find(int64_t(q.x), int64_t(q.y), int64_t(q.z), access, r)) return {};
  VoxelSample s;
  s.opacity = lv->opacity(r.index);
  s.projected = s.opacity * lv->axisFractionAt(r.index);
  s.radiance = lv->radianceAt(r);
  s.normal = lv->normalAt(r.index);
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
    if (finest) row("diffuse", lv.diffuse.bytes(), 0.0);
    row("radiance", lv.radiance[0].bytes(), finest ? m_impl->main.injectSeconds : 0.0);
    row("radiance_back", lv.radiance[1].bytes(), 0.0);
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
              lv.diffuse.bytes() + lv.radiance[0].bytes() + lv.radiance[1].bytes() +
              lv.coneTable.capacity() * sizeof(ConeVoxel);
    s.seconds = lv.buildSeconds;
    rows.push_back(s);
  }
  return rows;
}

nlohmann::json VoxelField::quantizationJson() const {
  const FieldQuantization& q = m_impl->quant;
  if (!m_impl->settings.measureQuantization) return nullptr;
  return {{"coverage_relative", q.coverage.json()}, {"normal_degrees", q.normal.json()},
          {"radiance_relative", q.radiance.json()}, {"axes_absolute", q.axes.json()}, {"diffuse_absolute", q.diffuse.json()}};
}

uint64_t VoxelField::memoryBytes() const {
  uint64_t total = 0;
  for (const VoxelGridStats& s : stats()) total += s.bytes;
  return total;
}

namespace {

/// Version of the .vdb layout VoxelField::write produces and VoxelField::read accepts.
constexpr int32_t kFieldFileVersion = 2;

/// OpenVDB puts voxel centres at integer index coordinates: voxel (i, j, k) of ours has its
/// centre at origin + (i + 0.5) * voxelSize.
openvdb::math::Transform::Ptr transformFor(const DVec3& origin, double voxelSize) {
  auto xform = openvdb::math::Transform::createLinearTransform(voxelSize);
  xform->postTranslate(openvdb::Vec3d(origin.x, origin.y, origin.z) + openvdb::Vec3d(0.5 * voxelSize));
  return xform;
}

/// The grids of one level under `prefix` ("" for the main grid, "caustic_" for the caustic
/// grid): coverage and normal of every voxel; each side's radiance, the diffuse fraction and the
/// mips' axis fractions where they differ from their defaults (0, 1, none). Each is a task that
/// builds it (write() runs them in parallel), in file order.
using GridTask = std::function<openvdb::GridBase::Ptr()>;
void addLevelGrids(const Level& lv, const DVec3& origin, bool finest, const std::string& prefix, std::vector<GridTask>& tasks) {
  const std::string l = "_L" + std::to_string(lv.level);
  const openvdb::math::Transform::Ptr xform = transformFor(origin, lv.voxelSize);
  auto floatGrid = [&lv, xform, l, prefix](const std::string& name, float background, bool all, auto value) -> GridTask {
    return [=, &lv]() -> openvdb::GridBase::Ptr {
      auto grid = openvdb::FloatGrid::create(background);
      grid->setName(prefix + name + l);
      grid->setTransform(xform->copy());
      grid->setGridClass(openvdb::GRID_FOG_VOLUME);
      auto acc = grid->getAccessor();
      lv.forEachVoxel([&](const VoxelRef& r, uint32_t i, uint32_t j, uint32_t k) {
        const float v = value(r);
        if (all || v != background) acc.setValue(openvdb::Coord(int32_t(i), int32_t(j), int32_t(k)), v);
      });
      return grid;
    };
  };
  auto vecGrid = [&lv, xform, l, prefix](const std::string& name, bool all, auto value) -> GridTask {
    return [=, &lv]() -> openvdb::GridBase::Ptr {
      auto grid = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.0f));
      grid->setName(prefix + name + l);
      grid->setTransform(xform->copy());
      auto acc = grid->getAccessor();
      lv.forEachVoxel([&](const VoxelRef& r, uint32_t i, uint32_t j, uint32_t k) {
        const Vec3 x = value(r);
        if (all || !isBlack(x))
          acc.setValue(openvdb::Coord(int32_t(i), int32_t(j), int32_t(k)), openvdb::Vec3s(x.x, x.y, x.z));
      });
      return grid;
    };
  };
  const Level* level = &lv;
  // The coverage grid's active voxels are the level's (a sliver's coverage may round to zero
  // in half precision: it stays active).
  tasks.push_back(floatGrid("coverage", 0.0f, true, [level](const VoxelRef& r) { return float(level->coverage[r.index]); }));
  tasks.push_back(vecGrid("normal", true, [level](const VoxelRef& r) { return level->normalAt(r.index); }));
  if (lv.lit) {
    tasks.push_back(vecGrid("radiance", false, [level](const VoxelRef& r) { return level->frontAt(r); }));
    tasks.push_back(vecGrid("radiance_back", false, [level](const VoxelRef& r) { return level->backAt(r); }));
  }
  if (!lv.axisFraction.empty())
    tasks.push_back(vecGrid("axes", true, [level](const VoxelRef& r) { return level->axisFractionAt(r.index); }));
  if (finest) tasks.push_back(floatGrid("diffuse", 1.0f, false, [level](const VoxelRef& r) { return level->diffuseAt(r); }));
}

/// One level back from the grids addLevelGrids wrote (missing grids: their defaults).
Level readLevel(openvdb::io::File& file, const std::string& path, const std::string& prefix, int level, double voxelSize,
                bool mip) {
  const std::string l = "_L" + std::to_string(level);
  auto grid = [&](const std::string& name, bool required) -> openvdb::GridBase::Ptr {
    if (!file.hasGrid(prefix + name + l)) {
      if (required) throw Error(path + ": not a voxcone field: no grid '" + prefix + name + l + "'");
      return nullptr;
    }
    return file.readGrid(prefix + name + l);
  };
  auto typed = [&](auto tag, const openvdb::GridBase::Ptr& g, const std::string& name) {
    using GridT = typename decltype(tag)::type;
    auto t = openvdb::gridPtrCast<GridT>(g);
    if (g && !t) throw Error(path + ": grid '" + prefix + name + l + "' has type " + g->type() + ", not " + GridT::gridType());
    return t;
  };
  struct FloatTag { using type = openvdb::FloatGrid; };
  struct VecTag { using type = openvdb::Vec3SGrid; };
  const auto coverage = typed(FloatTag{}, grid("coverage", true), "coverage");
  const auto normal = typed(VecTag{}, grid("normal", true), "normal");
  const auto front = typed(VecTag{}, grid("radiance", false), "radiance");
  const auto back = typed(VecTag{}, grid("radiance_back", false), "radiance_back");
  const auto axes = typed(VecTag{}, grid("axes", mip), "axes");
  const auto diffuse = typed(FloatTag{}, grid("diffuse", false), "diffuse");
  if (bool(front) != bool(back)) throw Error(path + ": grid '" + prefix + "radiance" + l + "' needs its '_back' grid");

  // The voxels in key order, from the coverage grid's active voxels.
  const int64_t res = int64_t(1) << level;
  std::vector<uint64_t> keys;
  keys.reserve(size_t(coverage->activeVoxelCount()));
  for (auto it = coverage->tree().cbeginValueOn(); it; ++it) {
    const openvdb::Coord c = it.getCoord();
    if (c.x() < 0 || c.y() < 0 || c.z() < 0 || c.x() >= res || c.y() >= res || c.z() >= res || !(*it >= 0.0f && *it <= 65504.0f))
      throw Error(path + ": grid '" + prefix + "coverage" + l + "' has a voxel outside the level or a coverage out of range");
    keys.push_back(voxel::packKey(uint32_t(c.x()), uint32_t(c.y()), uint32_t(c.z())));
  }
  tbb::parallel_sort(keys.begin(), keys.end());

  LevelBuilder builder(level, voxelSize);
  auto covAcc = coverage->getConstAccessor();
  auto nrmAcc = normal->getConstAccessor();
  std::optional<openvdb::Vec3SGrid::ConstAccessor> frontAcc, backAcc, axesAcc;
  std::optional<openvdb::FloatGrid::ConstAccessor> diffAcc;
  if (front) frontAcc.emplace(front->getConstAccessor()), backAcc.emplace(back->getConstAccessor());
  if (axes) axesAcc.emplace(axes->getConstAccessor());
  if (diffuse) diffAcc.emplace(diffuse->getConstAccessor());
  const auto vec = [](const openvdb::Vec3s& v) { return Vec3(v.x(), v.y(), v.z()); };
  constexpr size_t kRun = 1 << 16;
  VoxelArrays run;
  for (size_t first = 0; first < keys.size(); first += kRun) {
    run.clear();
    for (size_t n = first; n < std::min(keys.size(), first + kRun); ++n) {
      uint32_t i, j, k;
      voxel::unpackKey(keys[n], i, j, k);
      const openvdb::Coord c{int32_t(i), int32_t(j), int32_t(k)};
      run.keys.push_back(keys[n]);
      run.coverage.push_back(covAcc.getValue(c));
      run.normal.push_back(vec(nrmAcc.getValue(c)));
      if (!mip) run.diffuse.push_back(diffAcc ? diffAcc->getValue(c) : 1.0f);
      if (front) {
        run.radiance.push_back(vec(frontAcc->getValue(c)));
        run.radianceBack.push_back(vec(backAcc->getValue(c)));
      }
      if (axes) run.axisFraction.push_back(vec(axesAcc->getValue(c)));
    }
    builder.append(run);
  }
  Level out = builder.finish();
  out.lit = bool(front);
  return out;
}

}  // namespace

void VoxelField::write(const std::string& path, const nlohmann::json& metadata) const {
  std::call_once(g_openvdbInit, [] { openvdb::initialize(); });
  const Impl& f = *m_impl;
  std::vector<GridTask> tasks;
  for (const Level& lv : f.main.levels) addLevelGrids(lv, f.origin, &lv == &f.main.levels.front(), "", tasks);
  for (const Level& lv : f.caustic.levels) addLevelGrids(lv, f.origin, true, "caustic_", tasks);
  openvdb::GridPtrVec grids(tasks.size());
  tbb::parallel_for(size_t(0), tasks.size(), [&](size_t t) { grids[t] = tasks[t](); });

  openvdb::MetaMap meta;
  // The caller's keys go under "voxcone:" so they never clash with the typed keys below.
  if (metadata.is_object())
    for (auto it = metadata.begin(); it != metadata.end(); ++it)
      meta.insertMeta("voxcone:" + it.key(),
                      openvdb::StringMetadata(it->is_string() ? it->get<std::string>() : it->dump()));
  meta.insertMeta("field_version", openvdb::Int32Metadata(kFieldFileVersion));
  meta.insertMeta("level", openvdb::Int32Metadata(f.settings.level));
  meta.insertMeta("coarsest_level", openvdb::Int32Metadata(f.settings.coarsestLevel));
  meta.insertMeta("caustic_level", openvdb::Int32Metadata(f.caustic.empty() ? 0 : f.settings.causticLevel));
  meta.insertMeta("kernel_sigma", openvdb::FloatMetadata(f.settings.kernelSigmaVoxels));
  meta.insertMeta("padding", openvdb::DoubleMetadata(f.settings.padding));
  meta.insertMeta("mip_filter", openvdb::StringMetadata(f.settings.mipFilter == MipFilter::Box ? "box" : "gaussian"));
  meta.insertMeta("voxel_size", openvdb::DoubleMetadata(f.voxelSize(f.settings.level)));
  meta.insertMeta("origin", openvdb::Vec3DMetadata(openvdb::Vec3d(f.origin.x, f.origin.y, f.origin.z)));
  meta.insertMeta("extent", openvdb::DoubleMetadata(f.extent));
  meta.insertMeta("surface_area", openvdb::DoubleMetadata(f.surfaceArea));
  meta.insertMeta("injected_power", openvdb::Vec3DMetadata(openvdb::Vec3d(f.injected.x, f.injected.y, f.injected.z)));
  meta.insertMeta("dropped_power", openvdb::Vec3DMetadata(openvdb::Vec3d(f.dropped.x, f.dropped.y, f.dropped.z)));
  meta.insertMeta("global_photons", openvdb::Int64Metadata(int64_t(f.globalPhotons)));
  meta.insertMeta("caustic_photons", openvdb::Int64Metadata(int64_t(f.causticPhotons)));
  char hash[17];
  std::snprintf(hash, sizeof hash, "%016llx", (unsigned long long)f.sceneHash);
  meta.insertMeta("scene_hash", openvdb::StringMetadata(hash));

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

VoxelField VoxelField::read(const std::string& path) {
  std::call_once(g_openvdbInit, [] { openvdb::initialize(); });
  VoxelField field;
  Impl& f = *field.m_impl;
  try {
    openvdb::io::File file(path);
    file.open(false);  // read every grid whole: each level is decoded once
    const openvdb::MetaMap::Ptr meta = file.getMetadata();
    auto need = [&](const char* key) {
      if (!(*meta)[key]) throw Error(path + ": not a voxcone field: no metadata '" + std::string(key) + "'");
    };
    need("field_version");
    const int32_t version = meta->metaValue<int32_t>("field_version");
    if (version != kFieldFileVersion)
      throw Error(path + ": voxcone field version " + std::to_string(version) + ", this build reads version " +
                  std::to_string(kFieldFileVersion) + " (voxelize the scene again)");
    for (const char* key : {"level", "coarsest_level", "caustic_level", "kernel_sigma", "padding", "mip_filter", "origin",
                            "extent", "surface_area", "injected_power", "dropped_power", "global_photons", "caustic_photons",
                            "scene_hash"})
      need(key);
    VoxelSettings& s = f.settings;
    s.level = meta->metaValue<int32_t>("level");
    s.coarsestLevel = meta->metaValue<int32_t>("coarsest_level");
    s.causticLevel = meta->metaValue<int32_t>("caustic_level");
    s.kernelSigmaVoxels = meta->metaValue<float>("kernel_sigma");
    s.padding = meta->metaValue<double>("padding");
    s.mipFilter = meta->metaValue<std::string>("mip_filter") == "gaussian" ? MipFilter::Gaussian : MipFilter::Box;
    if (s.level < 1 || s.level > 13 || s.coarsestLevel < 0 || s.coarsestLevel > s.level || s.causticLevel < 0 ||
        s.causticLevel > 13)
      throw Error(path + ": voxcone field with levels out of range (level " + std::to_string(s.level) + ", coarsest " +
                  std::to_string(s.coarsestLevel) + ", caustic " + std::to_string(s.causticLevel) + ")");
    const openvdb::Vec3d o = meta->metaValue<openvdb::Vec3d>("origin");
    f.origin = DVec3(o.x(), o.y(), o.z());
    f.originF = Vec3(f.origin);
    f.extent = meta->metaValue<double>("extent");
    if (!(f.extent > 0.0) || !std::isfinite(f.extent)) throw Error(path + ": voxcone field of extent " + std::to_string(f.extent));
    f.bounds = Bounds3(Vec3(f.origin), Vec3(f.origin + DVec3(f.extent)));
    f.surfaceArea = meta->metaValue<double>("surface_area");
    const openvdb::Vec3d inj = meta->metaValue<openvdb::Vec3d>("injected_power"),
                         drop = meta->metaValue<openvdb::Vec3d>("dropped_power");
    f.injected = DVec3(inj.x(), inj.y(), inj.z());
    f.dropped = DVec3(drop.x(), drop.y(), drop.z());
    f.globalPhotons = uint64_t(meta->metaValue<int64_t>("global_photons"));
    f.causticPhotons = uint64_t(meta->metaValue<int64_t>("caustic_photons"));
    f.sceneHash = std::strtoull(meta->metaValue<std::string>("scene_hash").c_str(), nullptr, 16);
    for (int level = s.level; level >= s.coarsestLevel; --level)
      f.main.levels.push_back(readLevel(file, path, "", level, f.voxelSize(level), level != s.level));
    if (s.causticLevel > 0)
      f.caustic.levels.push_back(readLevel(file, path, "caustic_", s.causticLevel, f.voxelSize(s.causticLevel), false));
    file.close();
  } catch (const openvdb::Exception& e) {
    throw Error(path + ": cannot read OpenVDB file: " + e.what());
  }
  for (Grid* grid : {&f.main, &f.caustic})
    for (Level& lv : grid->levels)
      if (lv.level <= kConeTableLevel && lv.lit) lv.buildConeTable();
  return field;
}

}  // namespace voxcone
