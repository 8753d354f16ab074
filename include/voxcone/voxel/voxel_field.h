#pragma once
/// \file voxel_field.h
/// The sparse voxel radiance field: scene surfaces voxelized into OpenVDB grids at a finest
/// level and its coarser mip levels (the octree), carrying opacity, normal and each side's
/// outgoing diffuse radiance from injected photons. OpenVDB types stay inside src/voxel/.
///
/// Levels: level L has 2^L voxels across the longest axis of the scene bounds (level 10 =
/// 1024 voxels across). Mip m of a field built at level L is level L - m.

#include "voxcone/core/bounds.h"
#include "voxcone/core/progress.h"

#include <nlohmann/json_fwd.hpp>

#include <memory>
#include <string>
#include <vector>

namespace voxcone {

class Scene;
struct PhotonMaps;
struct Photon;

/// Voxelization and injection settings.
/// The field's default margin: 1/16 of the scene's longest side on every side (so its side is
/// 1.125 times the scene's). Measured (256x256, 16 spp, 8 gathers, filter 8, level 6, against
/// path at 4096 spp): cornell-box 39.26 dB without a margin, 39.62 / 40.82 / 40.93 / 41.01 /
/// 40.32 / 40.12 dB at 1/64, 1/32, 1/25, 1/16, 3/40, 1/8; cornell-dragon 40.25 dB without,
/// 41.45 / 41.43 / 40.51 dB at 1/32, 1/16, 3/32. Without it the walls at the bounds' lower
/// corner (x = 0, y = 0) lie on the boundary face of every level's outer voxels: the ceiling's
/// indirect light (its cones end on the floor) was 13-16% dark and the short box's front 35%
/// bright; with it 8-12% and 20-23%.
constexpr double kDefaultFieldPadding = 1.0 / 16.0;

/// How a mip level is filtered from the next finer one (VoxelField::buildMips).
enum class MipFilter {
  Box,      ///< the mean of the 2x2x2 children
  Gaussian  ///< the binomial [1 3 3 1] / 8 per axis over the 4x4x4 children nearest the centre
};

/// The footprint of one lookup (VoxelField::coneSample) at voxel size v, as a variance per
/// axis: what the mips' prefilter spread plus the trilinear tent (variance v^2 / 6). The finest
/// level holds each surface's box average over its voxel (v0^2 / 12). A box mip adds the
/// spread of its 2 children (1/4 of a child voxel squared, v^2 / 16) and keeps v^2 / 12 at
/// every level; a Gaussian mip adds the binomial's (3/4 of a child voxel squared, 3 v^2 / 16),
/// which sums to v^2 / 4 - v0^2 / 6. A lookup of variance sigma^2 therefore takes
///   box:      v^2 = 4 sigma^2
///   Gaussian: v^2 = 12/5 sigma^2 + 2/5 v0^2   (5 v^2 / 12 - v0^2 / 6 = sigma^2)
/// i.e. v^2 = a sigma^2 + b v0^2 (tests/voxel: the measured variance of a lookup of a point).
struct LookupFootprint {
  float a = 4.0f, b = 0.0f;
  static LookupFootprint of(MipFilter filter) {
    return filter == MipFilter::Box ? LookupFootprint{4.0f, 0.0f} : LookupFootprint{2.4f, 0.4f};
  }
};

struct VoxelSettings {
  int level = 8;             ///< finest level, [1, 13]
  int coarsestLevel = 2;     ///< coarsest mip level built, [0, level]
  /// Standard deviation of the Gaussian photon footprint, in voxels of the finest level. The
  /// footprint's weights over the voxels holding surface sum to one (power is conserved).
  float kernelSigmaVoxels = 0.75f;
  /// Level of the caustic grid (finer than `level` for sharp caustics); 0: no caustic grid.
  int causticLevel = 0;
  /// Empty margin around the scene's bounds on every side, as a fraction of their longest side,
  /// so that no surface sits on the field's boundary (see kDefaultFieldPadding); [0, 1].
  double padding = kDefaultFieldPadding;
  MipFilter mipFilter = MipFilter::Box;
  /// Memory the field may take, bytes, checked before voxelizing (VoxelField::estimate): a
  /// level whose estimated peak exceeds it is refused with an error naming the finest level
  /// that fits. kAvailableMemory: the machine's available memory at that moment; kNoBudget: no check.
  uint64_t memoryBudgetBytes = kAvailableMemory;
  /// Measure the error each compact encoding adds against the full-precision values it
  /// encodes (VoxelField::quantizationJson; voxelize --json).
  bool measureQuantization = false;
  static constexpr uint64_t kAvailableMemory = 0;
  static constexpr uint64_t kNoBudget = ~uint64_t(0);
  /// memoryBudgetBytes of a budget in MB (10^6 bytes) as users give it: negative (not given)
  /// the available memory, 0 no budget.
  static uint64_t budgetFromMegabytes(double mb) {
    return mb < 0.0 ? kAvailableMemory : mb == 0.0 ? kNoBudget : uint64_t(mb * 1e6 < 1.0 ? 1.0 : mb * 1e6);
  }
};

/// The memory a field would take, estimated before voxelizing it (VoxelField::estimate).
struct FieldEstimate {
  int level = 0;                 ///< finest level
  uint64_t voxels = 0;           ///< active voxels at the finest level
  uint64_t fieldBytes = 0;       ///< every grid and mip, every voxel's radiance lit
  uint64_t peakBytes = 0;        ///< fieldBytes plus what voxelizing, injecting and the mips hold at once
  int probeLevel = 0;            ///< the level counted exactly (0: bounded from the triangles alone)
};

/// Memory and time of one grid at one level.
struct VoxelGridStats {
  std::string grid;          ///< "topology", "opacity", "normal", "axes" (mips), "diffuse" (finest), "radiance", "radiance_back", "cone_table", "caustic"
  int level = 0;
  double voxelSize = 0.0;    ///< world units
  uint64_t activeVoxels = 0;
  uint64_t leaves = 0;
  uint64_t bytes = 0;        ///< in memory
  double seconds = 0.0;      ///< time to build it
};

/// One voxel looked up at a (possibly fractional) level.
struct VoxelSample {
  float opacity = 0.0f;      ///< coverage in [0, 1]
  Vec3 radiance{0.0f};       ///< outgoing diffuse radiance, both sides summed (opacity-weighted mean), W/(sr m^2)
  Vec3 normal{0.0f};         ///< mean normal (not normalized: its length says how aligned)
  /// opacity times the mean |normal| per axis. A ray of unit direction d crossing the field
  /// meets surfaces at the rate dot(projected, |d|) / finest voxel size per unit length (the
  /// area density times the projected fraction, summed as if the axes' signs agreed): a plane
  /// crossed at any angle adds up to one crossing, at every level.
  Vec3 projected{0.0f};
};

/// What a cone of unit direction d takes from one lookup: VoxelSample reduced to the two
/// numbers the cone composites with, computed in float without normalizing normals.
struct ConeSample {
  /// dot(projected, |d|): surfaces met per finest voxel size of travel along d.
  float density = 0.0f;
  /// Radiance the cone sees: per voxel the side of its surface that faces the cone's apex
  /// (surfaces are two-sided and each side keeps its own light), weighted by the voxel's share
  /// of the density. Zero when density is zero.
  Vec3 radiance{0.0f};
};

/// The voxel field. Build, then inject photons, then build the mips.
class VoxelField {
public:
  VoxelField();
  ~VoxelField();
  VoxelField(VoxelField&&) noexcept;
  VoxelField& operator=(VoxelField&&) noexcept;

  /// Voxelize the scene's surfaces at settings.level: only voxels a triangle passes through
  /// are active (triangle-box overlap, Akenine-Möller 2001); per voxel the surface area inside
  /// it, the area-weighted normal and the diffuse part of that area (mirrors, metals and glossy
  /// surfaces get opacity but gather no light; photons bring the albedo, Photon::albedo). Smooth glass (Material::isClearGlass: Dielectric, ThinDielectric) is left out: a
  /// cone's lookups see through it to what it passes on, unbent, and its exact axis ray
  /// refracts through it (ConeTracer); as a black occluder it cost the glass dragon 0.7 dB at
  /// 4 spp. Throws SettingsError for bad settings (and a scene of glass alone: nothing to hold).
  /// With `causticPhotons`, the caustic grid (settings.causticLevel) holds only the voxels
  /// those photons' footprints reach (what inject keeps of it anyway), instead of the whole
  /// scene at that level; without, it is voxelized whole.
  /// Throws SettingsError before allocating when the estimate (estimate()) exceeds
  /// settings.memoryBudgetBytes.
  static VoxelField voxelize(const Scene& scene, const VoxelSettings& settings, Progress* progress = nullptr,
                             const std::vector<Photon>* causticPhotons = nullptr);

  /// The memory of the main grid at settings.level, from a cheap count: the active voxels and
  /// bricks of a probe level (level - 2, at most 9) voxelized exactly and streamed away, and
  /// per finest level the bricks of level L taken as the probe's voxels two levels down, the
  /// voxels per brick as the probe's (surfaces fill bricks alike at every level), the stated
  /// bytes per voxel and per brick of each grid (src/voxel/level.h), every voxel lit. With
  /// `quick`, first an upper bound from the triangles' voxel boxes, and the count only when the
  /// bound exceeds `budget`. Rows for every finest level from settings.coarsestLevel up to
  /// settings.level. Measured against the built fields in tests/voxel.
  static std::vector<FieldEstimate> estimate(const Scene& scene, const VoxelSettings& settings, bool quick = false,
                                             uint64_t budget = 0);

  /// Splat each photon's reflected power (power * Photon::albedo) into the finest level with a
  /// normalized Gaussian footprint and turn it into outgoing radiance L = Phi_r / (pi A), A the
  /// voxel's surface area: the mean over that surface of albedo / pi * E. Caustic
  /// photons go to the main grid too (it holds all diffuse radiance: the global map covers
  /// every light path but L S+ D, the caustic map those) and to the caustic grid when
  /// settings.causticLevel > 0. Identical at any thread count.
  /// Each voxel keeps the two sides of its surface apart (front: the side its wound mean
  /// normal points to): a panel lit from above stays dark below. The footprint covers the
  /// active voxels within 3 sigma that hold diffuse surface and whose mean normal lies within 60
  /// degrees of the photon's normal (the same surface, not another across a crease), on their
  /// front; where there is none, those within 60 degrees of its opposite, on their back (an
  /// open panel lit from behind its winding). Weights exp(-d^2 / 2 sigma^2) times the voxel's
  /// diffuse surface area, normalized to one. Without such a voxel the photon goes to the voxel
  /// containing it, on the side it arrived on, else it is dropped (droppedPower()). Replaces
  /// earlier injections and drops the mips built from them: call buildMips again.
  void inject(const PhotonMaps& photons, Progress* progress = nullptr);

  /// Build levels level-1 ... coarsestLevel by restriction (settings.mipFilter: the 2x2x2
  /// children's mean, or the binomial over 4x4x4): opacity = weighted mean coverage of the
  /// children; each child turned to agree with the most opaque one (two-sided
  /// surfaces: front and back swap when turned), then normal = opacity-weighted sum
  /// (renormalized), front and back radiance = opacity-weighted means, opacity-weighted mean
  /// |normal| per axis (for VoxelSample::projected).
  /// The diffuse fraction stays at the finest level only (injection alone reads it).
  void buildMips(Progress* progress = nullptr);

  /// What build() and relight() took: each stage's seconds and the process's peak resident
  /// set after it (peakRssBytes: its high-water mark so far).
  struct BuildStats {
    double voxelizeSeconds = 0.0, injectSeconds = 0.0, mipsSeconds = 0.0;
    uint64_t peakAfterVoxelize = 0, peakAfterInject = 0, peakAfterMips = 0;
  };
  /// The photons-to-field pipeline that `voxcone voxelize` and the voxcone integrator both run:
  /// voxelize (the caustic grid only where `traced`'s caustic photons land), inject `held` (the
  /// photons the field is to hold: all of `traced`, or its caustic ones alone where the cones
  /// read photons, not voxels) and build the mips.
  static VoxelField build(const Scene& scene, const VoxelSettings& settings, const PhotonMaps& traced,
                          const PhotonMaps& held, Progress* progress = nullptr, BuildStats* stats = nullptr);
  /// build()'s last two stages on a field already voxelized: inject `held` (replacing what it
  /// held) and build the mips again (a progressive render's next pass keeps the voxels).
  void relight(const PhotonMaps& held, Progress* progress = nullptr, BuildStats* stats = nullptr);

  const VoxelSettings& settings() const;
  /// The scene bounds the grid covers (a cube anchored at the scene's lower corner).
  const Bounds3& bounds() const;
  /// Voxel size of `level`, world units.
  double voxelSize(int level) const;
  /// Levels built so far, finest first.
  std::vector<int> levels() const;

  /// The voxel containing worldPos at `level` (nearest, no filtering); zero outside.
  VoxelSample lookup(const Vec3& worldPos, int level) const;
  /// Trilinear at an integer level, linear between levels for fractional `level` (what cones use).
  VoxelSample sample(const Vec3& worldPos, float level) const;
  /// sample(worldPos, level) as a cone of unit direction `dir` from `apex` sees it (the cones'
  /// hot path): each voxel shows the side of its surface that faces the apex.
  ConeSample coneSample(const Vec3& worldPos, float level, const Vec3& dir, const Vec3& apex) const;
  /// Caustic radiance at worldPos (trilinear in the caustic grid); zero without one.
  /// `viewFrom`: a point on the viewer's side of the surface, more than a caustic voxel away
  /// (the caustic light of the surface's other side stays there).
  Vec3 causticRadiance(const Vec3& worldPos, const Vec3& viewFrom) const;

  /// Photon power (W per channel) the last inject() put into the finest level (before the
  /// albedo: what conservation tests compare with the photons' sum).
  Vec3 injectedPower() const;
  /// Photon power (W per channel) of the last inject() that found no active voxel: photons
  /// outside every voxel's surface are dropped and counted here.
  Vec3 droppedPower() const;
  /// Total surface area (world units squared) the finest level holds: the sum over voxels of
  /// the area inside each voxel.
  double surfaceArea() const;
  /// Active voxels at `level` (0 when the level is not built).
  uint64_t activeVoxels(int level) const;

  /// One row per grid and level.
  std::vector<VoxelGridStats> stats() const;
  /// With settings.measureQuantization: per attribute of the main grid the largest and the
  /// mean error its encoding added (coverage and radiance relative, normals in degrees, axis
  /// and diffuse fractions absolute); null without.
  nlohmann::json quantizationJson() const;
  /// Bytes in memory of everything the field holds.
  uint64_t memoryBytes() const;

  /// Write every grid and level into one .vdb file, in standard OpenVDB grid types, voxel
  /// (i, j, k) centred at index (i, j, k): per level L of the main grid FloatGrid
  /// "coverage_L<L>" (surface area / voxel size^2 at the finest level, opacity = min(1,
  /// coverage); opacity in the mips), Vec3SGrid "normal_L<L>" (unit), "radiance_L<L>" and
  /// "radiance_back_L<L>" (each side's outgoing radiance, W/(sr m^2), where nonzero), the mips'
  /// "axes_L<L>" and the finest level's "diffuse_L<L>" (where not 1); the caustic grid's the
  /// same with the prefix "caustic_". File metadata: `metadata` (top-level keys as strings
  /// named "voxcone:<key>") and what read() needs (levels, the cube, settings, photon counts,
  /// field_version). Atomic. Throws Error.
  void write(const std::string& path, const nlohmann::json& metadata) const;
  /// A field back from write()'s file: the same voxels and values, bit for bit (every stored
  /// encoding survives its decoding: tests/voxel). Throws Error naming the file for a file that
  /// is not a voxcone field of this version.
  static VoxelField read(const std::string& path);
  /// Throws SettingsError (naming `what`) unless the field covers the cube voxelize() would
  /// give `scene` (a field of another scene, or of a moved one).
  void checkScene(const Scene& scene, const std::string& what) const;

private:
  struct Impl;
  std::unique_ptr<Impl> m_impl;
};

}  // namespace voxcone
