#pragma once
/// \file level.h (private to src/voxel/)
/// One level of the sparse voxel field: an OpenVDB topology tree whose active values index a
/// table of superbricks, and per-voxel attributes stored compactly as structure-of-arrays.
/// The files of src/voxel/ that include it (its headers are slow to compile): level.cpp,
/// mips.cpp, inject.cpp, lookup.cpp, voxel_field.cpp and field_io.cpp.
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

#include "field_common.h"
#include "voxelize.h"

#include "voxcone/voxel/voxel_field.h"

#include <Imath/half.h>
#include <nlohmann/json.hpp>
#include <openvdb/tree/Tree.h>
#include <openvdb/tree/ValueAccessor.h>

#include <memory>
#include <vector>

namespace voxcone {
namespace voxel {

using Half = Imath::half;
/// Brick coordinate -> brick index. Only active values are meaningful.
using IndexTree = openvdb::tree::Tree4<uint32_t, 4, 3, 2>::Type;
/// A read-only accessor that does not register with the tree (cheap to make per query).
using IndexAccessor = openvdb::tree::ValueAccessor<const IndexTree, false>;

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

/// Builds a level from runs of full-precision voxels in key order (VoxelSink), encoding each
/// run as it comes: the level never exists in full precision. With `quant`, the error of every
/// encoding is measured into it (level.cpp).
class LevelBuilder {
public:
  LevelBuilder(int level, double voxelSize, FieldQuantization* quant = nullptr);
  ~LevelBuilder();
  void append(const VoxelArrays& a);
  Level finish();

private:
  /// The error of voxel v's encodings (the ones append just stored).
  void measure(const VoxelArrays& a, size_t v);
  /// The brick just completed: its diffuse fractions and each side's radiance are kept only
  /// when some voxel of it needs them (SparseBricks).
  void flushBrick();

  FieldQuantization* m_quant = nullptr;
  Level m_out;
  std::unique_ptr<openvdb::tree::ValueAccessor<IndexTree>> m_acc;
  uint64_t m_lastBrick = ~uint64_t(0), m_lastSuper = ~uint64_t(0);
  std::vector<uint8_t> m_diffuse;   ///< the current brick's
  std::vector<uint32_t> m_radiance[2];  ///< the current brick's
};

/// A field's levels, finest first.
struct LevelStack {
  std::vector<Level> levels;
  double injectSeconds = 0.0;
  bool empty() const { return levels.empty(); }
  const Level* find(int level) const {
    if (levels.empty()) return nullptr;
    const int m = levels.front().level - level;
    return m >= 0 && m < int(levels.size()) ? &levels[size_t(m)] : nullptr;
  }
};


/// One coarser level from `child` (mips.cpp).
Level restrictLevel(const Level& child, MipFilter filter, FieldQuantization* quant);

/// The voxels of `lv` with nonzero radiance, as a level of their own (inject.cpp).
Level keepLit(const Level& lv);

}  // namespace voxel
}  // namespace voxcone
