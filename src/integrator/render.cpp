// The render driver (integrator.h renderImage): tiles of pixels in parallel, in passes without the
// indirect filter, or with it in stages (samples, link, gathers, filter); and the samples of
// chosen pixels (renderPixels).

#include "voxcone/accel/accel.h"
#include "voxcone/core/error.h"
#include "voxcone/core/rng.h"
#include "voxcone/core/timer.h"
#include "voxcone/image/film.h"
#include "voxcone/integrator/indirect_filter.h"
#include "voxcone/integrator/integrator.h"
#include "voxcone/integrator/voxel_cone/screen_space_gather.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>

namespace voxcone {

namespace {
/// Pixels whose samples' first-hit normals differ by more than this (8 degrees) saw more than
/// one surface (an edge or a crease inside the pixel): their indirect light is not filtered.
/// Measured (256x256 defaults): 0.9 instead leaves cornell-box at 38.28 dB (38.27) and lifts
/// cornell-dragon from 39.00 to 39.32 dB, since most of the dragon's pixels span facets a few
/// degrees apart; the stricter value is kept until the studies are re-run with it.
constexpr float kOneSurfaceNormalCos = 0.99f;

/// Pixels per side of the square tiles the pixels are rendered in, in parallel.
constexpr int kTile = 16;

/// A radiance estimate the image takes: finite and not negative.
bool usableRadiance(const Vec3& v) { return isFinite(v) && v.x >= 0.0f && v.y >= 0.0f && v.z >= 0.0f; }

/// A gather liSplit deferred, at its pixel.
struct PendingGather {
  size_t pixel = 0;
  DeferredGather gather;
};

/// A sample of a pixel the filter does not take (an edge, a crease, several surfaces), at its
/// first hit's filterable surface.
struct EdgeSample {
  size_t pixel = 0;
  Vec3 position{0.0f}, normal{0.0f};
  uint32_t material = 0;
  Vec3 albedo{1.0f};  ///< IndirectSplit::albedo
};

/// Filter pixels an edge sample may take its indirect light from: within this many pixels.
/// Measured (256x256, 4 spp, defaults): radius 1 / 2 / 3 let 2,352 / 2,361 / 2,363 of
/// cornell-box's edge pixels borrow (35.862 / 35.866 / 35.866 dB) and 3,267 / 3,622 / 3,836 of
/// cornell-dragon's (36.10 / 36.13 / 36.15 dB, 6,173 / 5,820 / 5,606 gathers); 2 keeps the light
/// from the pixel's own neighbourhood at nearly all of the gain.
constexpr int kBorrowRadius = 2;

/// For each edge sample, the nearest filterable pixel within kBorrowRadius on its surface
/// (onFilterSurface) whose point it sees along the surface (ScreenSpaceGather::linkedPoints), or -1.
/// Offsets are tried by distance, then row, then column: deterministic.
std::vector<int64_t> borrowFrom(const ScreenSpaceGather& gather, const IndirectBuffer& ib,
                                const std::vector<EdgeSample>& edges) {
  std::vector<std::pair<int, int>> offsets;
  for (int dy = -kBorrowRadius; dy <= kBorrowRadius; ++dy)
    for (int dx = -kBorrowRadius; dx <= kBorrowRadius; ++dx)
      if (dx != 0 || dy != 0) offsets.emplace_back(dx, dy);
  std::stable_sort(offsets.begin(), offsets.end(), [](const auto& a, const auto& b) {
    return a.first * a.first + a.second * a.second < b.first * b.first + b.second * b.second;
  });
  std::vector<int64_t> from(edges.size(), -1);
  tbb::parallel_for(size_t(0), edges.size(), [&](size_t i) {
    const EdgeSample& e = edges[i];
    const int x = int(e.pixel % size_t(ib.width)), y = int(e.pixel / size_t(ib.width));
    for (const auto& [dx, dy] : offsets) {
      const int qx = x + dx, qy = y + dy;
      if (qx < 0 || qy < 0 || qx >= ib.width || qy >= ib.height) continue;
      const size_t q = size_t(qy) * size_t(ib.width) + size_t(qx);
      if (!onFilterSurface(ib, q, e.position, e.normal, e.material)) continue;
      // Both ends a quarter of q's footprint above the surface (as linkIndirect's links).
      const float lift = 0.25f * ib.footprint[q];
      if (!gather.linkedPoints(e.position + e.normal * lift, ib.position[q] + ib.normal[q] * lift)) continue;
      from[i] = int64_t(q);
      return;
    }
  });
  return from;
}

/// Whether pixel (x, y) is its spacing x spacing block's gathering pixel: one per block, at an
/// offset drawn per block from the seed (a regular lattice would alias with the scene's edges).
bool gathersInBlock(int x, int y, int spacing, uint64_t seed) {
  if (spacing <= 1) return true;
  const uint64_t block = (uint64_t(uint32_t(y / spacing)) << 32) | uint32_t(x / spacing);
  const uint64_t hash = mixBits(block ^ mixBits(seed ^ 0x9e3779b97f4a7c15ull));
  const int s = spacing;
  return x % s == int(hash % uint64_t(s)) && y % s == int((hash >> 32) % uint64_t(s));
}

/// Run the deferred gathers `pending` (in parallel, each on its own), and add each pixel's
/// weighted gathers, in the list's order, to its indirect light.
/// Throws CancelledError when `progress` reports cancellation.
void runGathers(const ScreenSpaceGather& gather, const std::vector<PendingGather>& pending, int spp, IndirectBuffer& ib,
                uint64_t& invalid, Progress* progress) {
  std::vector<Vec3> value(pending.size(), Vec3(0.0f));
  constexpr size_t kChunk = 64;
  const size_t chunks = (pending.size() + kChunk - 1) / kChunk;
  std::atomic<bool> cancelled{false};
  if (progress) progress->start("gather", chunks);
  tbb::parallel_for(size_t(0), chunks, [&](size_t chunk) {
    if (cancelled.load(std::memory_order_relaxed)) return;
    if (progress && progress->cancelled()) {
      cancelled = true;
      return;
    }
    for (size_t i = chunk * kChunk; i < std::min(pending.size(), (chunk + 1) * kChunk); ++i)
      value[i] = pending[i].gather.weight * gather.gatherDeferred(pending[i].gather);
    if (progress) progress->advance(1);
  });
  if (cancelled) throw CancelledError();
  if (progress) progress->finish();
  std::vector<DVec3> sum(ib.indirect.size(), DVec3(0.0));
  for (size_t i = 0; i < pending.size(); ++i) {
    if (usableRadiance(value[i])) sum[pending[i].pixel] += DVec3(value[i]);
    else ++invalid;
  }
  // Pixels without a gather add zero.
  for (size_t p = 0; p < sum.size(); ++p) ib.indirect[p] += Vec3(sum[p] / double(spp));
}

/// The AOV layers' values of each sample, from the sample's camera ray and its RadianceTerms,
/// added to a film's layers: the film's layer i is the request's layer i (aovFilmLayers).
class AovSampler {
public:
  AovSampler(const Scene& scene, const AovRequest* request) : m_scene(scene) {
    if (!request || request->layers.empty()) return;
    m_request = request;
    for (Aov a : request->layers) {
      m_firstHit = m_firstHit || !isTermAov(a);
      m_terms = m_terms || isTermAov(a);
    }
  }
  /// Whether layers are asked for.
  bool active() const { return m_request != nullptr; }
  /// Whether a term layer is asked for (samples then go through liTerms).
  bool terms() const { return m_terms; }

  /// Add one sample of `pixel` to `film`.
  void add(Film& film, size_t pixel, const Ray& ray, const RadianceTerms& t) const {
    SurfaceHit sh;
    const bool hit = m_firstHit && intersectSurface(m_scene, *m_request->accel, ray, sh);
    for (size_t i = 0; i < m_request->layers.size(); ++i) {
      double* o = film.layerSums(pixel, i);
      const auto put = [o](const Vec3& v) {
        o[0] += double(v.x);
        o[1] += double(v.y);
        o[2] += double(v.z);
      };
      switch (m_request->layers[i]) {
        case Aov::Albedo:
          if (hit) {
            Material textured;
            const Material& m = m_scene.materialAt(sh, textured);
            put(m.hasDiffuseBase() ? m.albedo : m.specular);
          }
          break;
        case Aov::Normal:
          if (hit) put(glm::dot(sh.geomNormal, ray.dir) <= 0.0f ? sh.shadingNormal : -sh.shadingNormal);
          break;
        case Aov::Depth:
          if (hit) o[0] += double(glm::dot(sh.position - m_scene.camera.position(), m_scene.camera.forward()));
          break;
        case Aov::Emitted: put(t.emitted); break;
        case Aov::Direct: put(t.direct); break;
        case Aov::Caustic: put(t.caustic); break;
        case Aov::Indirect: put(t.indirect); break;
      }
    }
  }

  /// Add `v` to `pixel`'s sums of layer `a` in `film`, where it is asked for.
  void addTo(Film& film, size_t pixel, Aov a, const DVec3& v) const {
    if (!active()) return;
    for (size_t i = 0; i < m_request->layers.size(); ++i)
      if (m_request->layers[i] == a)
        for (int c = 0; c < 3; ++c) film.layerSums(pixel, i)[c] += v[c];
  }

private:
  const Scene& m_scene;
  const AovRequest* m_request = nullptr;
  bool m_firstHit = false, m_terms = false;
};

/// The film's layers for `request` (none without one), in the order asked.
std::vector<FilmLayer> aovFilmLayers(const AovRequest* request) {
  std::vector<FilmLayer> layers;
  if (request)
    for (Aov a : request->layers) layers.push_back({aovNames()[size_t(a)], aovChannels(a)});
  return layers;
}

/// The pixels that take glint samples (Integrator::glintSamples): those whose probe rays (the
/// centres of the pixel's 2 x 2 quarters) the integrator says may see glints vary
/// (glintsVary), and their eight neighbours. The probes are fixed rays, not the camera samples,
/// so which pixels take glint samples does not depend on those samples (an estimate chosen by
/// its own samples would be biased).
std::vector<uint8_t> glintPixels(const Scene& scene, const Integrator& integrator, int w, int h) {
  std::vector<uint8_t> probe(size_t(w) * size_t(h), 0u), out(probe.size(), 0u);
  tbb::parallel_for(0, h, [&](int y) {
    for (int x = 0; x < w; ++x) {
      Ray rays[4];
      for (int q = 0; q < 4; ++q)
        rays[q] = scene.camera.generateRay(float(x) + 0.25f + 0.5f * float(q & 1),
                                           float(y) + 0.25f + 0.5f * float(q >> 1), w, h);
      probe[size_t(y) * size_t(w) + size_t(x)] = integrator.glintsVary(rays, 4) ? 1u : 0u;
    }
  });
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int nx = x + dx, ny = y + dy;
          if (nx >= 0 && ny >= 0 && nx < w && ny < h && probe[size_t(ny) * size_t(w) + size_t(nx)])
            out[size_t(y) * size_t(w) + size_t(x)] = 1u;
        }
  return out;
}

/// Pixel (x, y)'s glint samples for its camera samples [first, first + count), `perSample` for
/// each, from a sampler of their own: their sum over perSample (what those camera samples' own
/// glints would add to the pixel's sum); unusable ones counted in `bad`.
DVec3 glintSum(const Scene& scene, const Integrator& integrator, const RenderSettings& settings, int x, int y,
               int perSample, int first, int count, uint64_t& bad) {
  const int w = settings.width, h = settings.height;
  const size_t pixel = size_t(y) * size_t(w) + size_t(x);
  Sampler sampler(settings.sampler, mixBits(settings.seed ^ 0x6c8e9cf570932bd5ULL), pixel,
                  uint32_t(settings.spp) * uint32_t(perSample));
  DVec3 sum(0.0);
  for (uint32_t s = uint32_t(first) * uint32_t(perSample); s < uint32_t(first + count) * uint32_t(perSample); ++s) {
    sampler.startSample(s);
    const Vec2 jitter = sampler.uniform2();
    const Ray ray = scene.camera.generateRay(float(x) + jitter.x, float(y) + jitter.y, w, h);
    const Vec3 G = integrator.liGlint(ray, sampler);
    if (usableRadiance(G)) sum += DVec3(G);
    else ++bad;
  }
  return sum / double(perSample);
}

/// Take a camera sample's glints out of its radiance and its terms (glintSum samples them).
void leaveOutGlints(Vec3& L, RadianceTerms& terms) {
  L -= terms.glint;
  terms.emitted -= terms.glint;
}

/// The glint samples a render takes (Integrator::glintSamples): how many per camera sample, and
/// at which pixels (glintPixels; none where the integrator takes none).
struct GlintPlan {
  int perSample = 0;
  std::vector<uint8_t> pixels;
  /// Whether `pixel` takes glint samples (its camera samples then leave their glints out).
  bool at(size_t pixel) const { return !pixels.empty() && pixels[pixel]; }
};

GlintPlan planGlints(const Scene& scene, const Integrator& integrator, int w, int h) {
  GlintPlan plan;
  plan.perSample = integrator.glintSamples();
  if (plan.perSample > 0) plan.pixels = glintPixels(scene, integrator, w, h);
  return plan;
}

/// One sample's radiance: li, or with AOVs liTerms, whose terms and first hit go into `film`'s
/// layers when the estimate is usable; without its glints where `glints` (glintSum takes them).
Vec3 takeSample(const Integrator& integrator, const Ray& ray, Sampler& sampler, size_t pixel, const AovSampler& aovs,
                Film& film, bool glints) {
  if (!aovs.active() && !glints) return integrator.li(ray, sampler);
  RadianceTerms terms;
  Vec3 L = aovs.terms() || glints ? integrator.liTerms(ray, sampler, nullptr, terms) : integrator.li(ray, sampler);
  if (glints) leaveOutGlints(L, terms);
  if (usableRadiance(L) && aovs.active()) aovs.add(film, pixel, ray, terms);
  return L;
}

/// Samples per pass of a render without the indirect filter: 1, 1, 2, 4, ... up to 64, so that
/// an interrupted render keeps complete passes of every pixel (at most 64 samples lost) and a
/// short one pays few passes. A pure function of spp: the same passes on every machine.
std::vector<int> passSizes(int spp) {
  std::vector<int> sizes;
  for (int done = 0, next = 1; done < spp; done += sizes.back()) {
    sizes.push_back(std::min(next, spp - done));
    if (sizes.size() > 1) next = std::min(2 * next, 64);
  }
  return sizes;
}

/// renderImage without the indirect filter, in passes over every pixel (passSizes). Each pixel

/// Pixel (x, y)'s samples [first, first + count) added to `film` (and its glint samples for
/// them, where it takes glint samples); unusable ones counted in `bad`.
void samplePixelPass(const Scene& scene, const Integrator& integrator, const RenderSettings& settings,
                     const GlintPlan& glints, const AovSampler& aovs, int x, int y, int first, int count, Film& film,
                     uint64_t& bad) {
  const int w = settings.width, h = settings.height;
  const size_t pixel = size_t(y) * size_t(w) + size_t(x);
  Sampler sampler(settings.sampler, settings.seed, pixel, static_cast<uint32_t>(settings.spp));
  const bool glint = glints.at(pixel);
  for (int s = first; s < first + count; ++s) {
    sampler.startSample(static_cast<uint32_t>(s));
    const Vec2 jitter = sampler.uniform2();
    const Ray ray = scene.camera.generateRay(float(x) + jitter.x, float(y) + jitter.y, w, h);
    const Vec3 L = takeSample(integrator, ray, sampler, pixel, aovs, film, glint);
    if (!usableRadiance(L)) ++bad;
    else film.beauty(pixel) += DVec3(L);
  }
  if (glint) {
    const DVec3 g = glintSum(scene, integrator, settings, x, y, glints.perSample, first, count, bad);
    film.beauty(pixel) += g;
    aovs.addTo(film, pixel, Aov::Emitted, g);
  }
}

/// renderImage without the indirect filter, in passes over every pixel (passSizes). Each pixel
/// sums its samples in sample order into one double sum whatever the passes, so the image is
/// the one a single pass gives, bit for bit. Cancellation is checked at every pixel of every
/// pass (a pixel's share of a pass is at most 64 samples: milliseconds), so a render stops
/// within a fraction of a second at any spp; with keepPartial it then returns the passes that
/// completed as an image of fewer samples (RenderResult::partial), else throws CancelledError.
RenderResult renderPasses(const Scene& scene, const Integrator& integrator, const RenderSettings& settings,
                          Progress* progress, bool keepPartial, const AovRequest* aovRequest) {
  const int w = settings.width, h = settings.height;
  const int tilesX = (w + kTile - 1) / kTile, tilesY = (h + kTile - 1) / kTile;
  Film film(w, h, aovFilmLayers(aovRequest));
  const AovSampler aovs(scene, aovRequest);
  std::atomic<uint64_t> invalid{0};
  uint64_t invalidComplete = 0;  // invalid after the last whole pass
  std::atomic<bool> cancelled{false};
  const std::vector<int> passes = passSizes(settings.spp);
  Timer timer;
  const GlintPlan glints = planGlints(scene, integrator, w, h);
  if (progress) progress->start("render", uint64_t(tilesX) * uint64_t(tilesY) * passes.size());
  int doneSpp = 0;
  for (const int passSpp : passes) {
    // One pass: every pixel's next passSpp samples, tile by tile in parallel.
    tbb::parallel_for(0, tilesX * tilesY, [&](int tile) {
      const int x0 = (tile % tilesX) * kTile, y0 = (tile / tilesX) * kTile;
      uint64_t bad = 0;
      for (int y = y0; y < std::min(y0 + kTile, h); ++y)
        for (int x = x0; x < std::min(x0 + kTile, w); ++x) {
          if (cancelled.load(std::memory_order_relaxed)) return;
          if (progress && progress->cancelled()) {
            cancelled = true;
            return;
          }
          samplePixelPass(scene, integrator, settings, glints, aovs, x, y, doneSpp, passSpp, film, bad);
        }
      invalid += bad;
      if (progress) progress->advance(1);
    });
    if (cancelled) break;
    doneSpp += passSpp;
    if (keepPartial && doneSpp < settings.spp) {
      film.keepComplete();
      invalidComplete = invalid;
    }
  }
  RenderResult result;
  result.completedSpp = doneSpp;
  if (cancelled) {
    if (!keepPartial || doneSpp == 0) throw CancelledError();
    film.restoreComplete();
    invalid = invalidComplete;
    result.partial = true;
  }
  if (progress) progress->finish();
  result.image = film.image(doneSpp);
  result.layers = film.layers(doneSpp);
  result.stageSeconds["samples"] = timer.seconds();
  result.seconds = timer.seconds();
  result.samples = uint64_t(w) * uint64_t(h) * uint64_t(doneSpp);
  result.invalidSamples = invalid;
  return result;
}

/// Which pixels run their deferred gathers, and which edge pixels take their indirect light
/// from filter pixels instead (FilteredRender::planGathers).
struct GatherPlan {
  std::vector<uint8_t> gathers;   ///< per pixel: its deferred gathers run
  std::vector<EdgeSample> edges;  ///< the samples of the pixels the filter does not take, in tile order
  std::vector<int64_t> from;      ///< per edge sample: the filter pixel it borrows from (borrowFrom), or -1
  std::vector<uint8_t> borrows;   ///< per pixel: its edge samples take their filter pixels' light
  uint64_t unfilled = 0;          ///< pixels that gather because the filter cannot fill them
  uint64_t borrowing = 0;         ///< pixels that borrow
};

/// renderImage with the indirect filter (ScreenSpaceGather::indirectFilterRadius > 0), in four
/// stages: every pixel's samples in one pass, the indirect light of filterable first hits split
/// off into the filter's buffer (samplePixels); which pixels run their deferred gathers and which
/// edge pixels borrow their light (planGathers: "link"); the gathers ("gather"); the filter and
/// the borrowed light added to the image ("filter").
class FilteredRender {
public:
  FilteredRender(const Scene& scene, const Integrator& integrator, const ScreenSpaceGather& gather,
                 const RenderSettings& settings, Progress* progress, const AovRequest* aovRequest)
      : m_scene(scene), m_integrator(integrator), m_gather(gather), m_settings(settings), m_progress(progress),
        m_filterRadius(gather.indirectFilterRadius()), m_w(settings.width), m_h(settings.height),
        m_tilesX((m_w + kTile - 1) / kTile), m_tilesY((m_h + kTile - 1) / kTile),
        m_film(m_w, m_h, aovFilmLayers(aovRequest)), m_aovs(scene, aovRequest),
        m_tilePending(size_t(m_tilesX) * size_t(m_tilesY)), m_tileEdges(m_tilePending.size()) {
    const size_t n = size_t(m_w) * size_t(m_h);
    m_modulation.assign(n, Vec3(1.0f));
    m_ib.width = m_w;
    m_ib.height = m_h;
    m_ib.indirect.assign(n, Vec3(0.0f));
    m_ib.position.assign(n, Vec3(0.0f));
    m_ib.normal.assign(n, Vec3(0.0f));
    m_ib.material.assign(n, 0u);
    m_ib.footprint.assign(n, 0.0f);
    m_ib.filterable.assign(n, 0u);
    // World-space width of a pixel per unit distance from the camera.
    m_pixelAngle = 2.0f * std::tan(0.5f * scene.camera.fovYDeg() * kPi / 180.0f) / float(m_h);
  }

  RenderResult run() {
    RenderResult result;
    result.completedSpp = m_settings.spp;
    Timer timer;
    m_glints = planGlints(m_scene, m_integrator, m_w, m_h);
    if (m_glints.perSample > 0) result.stageSeconds["glint_probe"] = timer.seconds();
    samplePixels();
    result.stageSeconds["samples"] = timer.seconds();
    Timer stage;
    const GatherPlan plan = planGathers();
    result.stageSeconds["link"] = stage.seconds();
    stage.reset();
    runPlannedGathers(plan, result);
    result.stageSeconds["gather"] = stage.seconds();
    stage.reset();
    filter(plan, result);
    result.stageSeconds["filter"] = stage.seconds();
    result.seconds = timer.seconds();
    result.samples = static_cast<uint64_t>(m_w) * m_h * m_settings.spp;
    result.invalidSamples = m_invalid;
    return result;
  }

private:
  /// Every pixel's samples, tile by tile in parallel. Throws CancelledError.
  void samplePixels() {
    std::atomic<bool> cancelled{false};
    if (m_progress) m_progress->start("render", static_cast<uint64_t>(m_tilesX) * m_tilesY);
    tbb::parallel_for(0, m_tilesX * m_tilesY, [&](int tile) {
      if (cancelled.load(std::memory_order_relaxed)) return;
      if (m_progress && m_progress->cancelled()) {
        cancelled = true;
        return;
      }
      const int x0 = (tile % m_tilesX) * kTile, y0 = (tile / m_tilesX) * kTile;
      uint64_t bad = 0;
      std::vector<EdgeSample> pixelSamples;
      for (int y = y0; y < std::min(y0 + kTile, m_h); ++y)
        for (int x = x0; x < std::min(x0 + kTile, m_w); ++x) {
          // Checked at every pixel: a tile of many samples per pixel is seconds of work.
          if (m_progress && m_progress->cancelled()) {
            cancelled = true;
            return;
          }
          samplePixel(tile, x, y, bad, pixelSamples);
        }
      m_invalid += bad;
      if (m_progress) m_progress->advance(1);
    });
    if (cancelled) throw CancelledError();
    if (m_progress) m_progress->finish();
  }

  /// Pixel (x, y)'s samples (of tile `tile`): all but their split-off indirect light into the
  /// film; that light into the filter's buffer, or its deferred gathers into the tile's list;
  /// where the samples saw one surface the pixel is the filter's, else its samples are edge
  /// samples. Unusable samples counted in `bad`; `pixelSamples` is scratch space.
  void samplePixel(int tile, int x, int y, uint64_t& bad, std::vector<EdgeSample>& pixelSamples) {
    const size_t pixel = static_cast<size_t>(y) * static_cast<size_t>(m_w) + static_cast<size_t>(x);
    Sampler sampler(m_settings.sampler, m_settings.seed, pixel, static_cast<uint32_t>(m_settings.spp));
    // Sum in double so the mean does not depend on float rounding of a long sum.
    DVec3 sum(0.0), indirectSum(0.0), positionSum(0.0), albedoSum(0.0);
    int seen = 0;  // samples whose first hit split off its indirect light
    bool oneSurface = true;
    IndirectSplit first;
    pixelSamples.clear();
    // Glints from the glint samples: the camera samples leave theirs out.
    const bool glints = m_glints.at(pixel);
    for (int s = 0; s < m_settings.spp; ++s) {
      sampler.startSample(static_cast<uint32_t>(s));
      const Vec2 jitter = sampler.uniform2();
      const Ray ray = m_scene.camera.generateRay(static_cast<float>(x) + jitter.x, static_cast<float>(y) + jitter.y, m_w, m_h);
      IndirectSplit sp;
      RadianceTerms terms;
      Vec3 L = m_aovs.terms() || glints ? m_integrator.liTerms(ray, sampler, &sp, terms)
                                        : m_gather.liSplit(ray, sampler, sp);
      if (glints) leaveOutGlints(L, terms);
      if (!usableRadiance(L) || (sp.valid && !usableRadiance(sp.indirect))) {
        ++bad;
        oneSurface = false;
        continue;
      }
      if (m_aovs.active()) m_aovs.add(m_film, pixel, ray, terms);
      sum += DVec3(L);
      if (!sp.valid) {
        oneSurface = false;
        continue;
      }
      if (sp.deferred) m_tilePending[size_t(tile)].push_back({pixel, sp.gather});
      else indirectSum += DVec3(sp.indirect);
      positionSum += DVec3(sp.position);
      albedoSum += DVec3(sp.albedo);
      pixelSamples.push_back({pixel, sp.position, sp.normal, sp.material, sp.albedo});
      if (seen++ == 0) first = sp;
      else if (sp.material != first.material || glm::dot(sp.normal, first.normal) < kOneSurfaceNormalCos) oneSurface = false;
    }
    if (glints) {
      const DVec3 g = glintSum(m_scene, m_integrator, m_settings, x, y, m_glints.perSample, 0, m_settings.spp, bad);
      sum += g;
      m_aovs.addTo(m_film, pixel, Aov::Emitted, g);
    }
    // All but the split-off indirect light now, that after the filter.
    m_film.beauty(pixel) = sum;
    const DVec3 spp(m_settings.spp);
    m_ib.indirect[pixel] = Vec3(indirectSum / spp);
    if (seen > 0) m_modulation[pixel] = Vec3(albedoSum / double(seen));
    if (seen > 0 && oneSurface) {
      m_ib.position[pixel] = Vec3(positionSum / double(seen));
      m_ib.normal[pixel] = first.normal;
      m_ib.material[pixel] = first.material;
      m_ib.footprint[pixel] = std::max(1e-30f, m_pixelAngle * glm::length(m_ib.position[pixel] - m_scene.camera.position()));
      m_ib.filterable[pixel] = 1u;
    } else if (seen > 0) {
      m_tileEdges[size_t(tile)].insert(m_tileEdges[size_t(tile)].end(), pixelSamples.begin(), pixelSamples.end());
    }
  }

  /// Which pixels run their deferred gathers and which borrow; the filter's links
  /// (ScreenSpaceGather::linkIndirect) and its estimated pixels set in the buffer.
  GatherPlan planGathers() {
    GatherPlan plan;
    // Which pixels run their deferred gathers: one per block on the filter's surfaces, every
    // pixel off them (the filter keeps those as they are), and any the filter cannot fill.
    const int spacing = std::max(1, m_gather.gatherSpacing());
    plan.gathers.assign(size_t(m_w) * size_t(m_h), 1u);
    m_ib.estimated.assign(plan.gathers.size(), 1u);
    for (int y = 0; y < m_h; ++y)
      for (int x = 0; x < m_w; ++x) {
        const size_t p = size_t(y) * size_t(m_w) + size_t(x);
        if (m_ib.filterable[p] && !gathersInBlock(x, y, spacing, m_settings.seed)) plan.gathers[p] = m_ib.estimated[p] = 0u;
      }
    m_gather.linkIndirect(m_ib);
    if (spacing > 1) {
      const std::vector<uint8_t> unfilled = unfilledPixels(m_ib, m_filterRadius);
      for (size_t p = 0; p < unfilled.size(); ++p)
        if (unfilled[p]) {
          plan.gathers[p] = m_ib.estimated[p] = 1u;
          ++plan.unfilled;
        }
    }
    // Pixels the filter does not take: where each of their samples on a filterable surface
    // finds a filter pixel of that surface nearby, the sample takes that pixel's filtered light
    // and the pixel gathers nothing; any sample without one and the pixel gathers as before.
    for (const std::vector<EdgeSample>& t : m_tileEdges) plan.edges.insert(plan.edges.end(), t.begin(), t.end());
    m_tileEdges = {};
    plan.from = borrowFrom(m_gather, m_ib, plan.edges);
    plan.borrows.assign(plan.gathers.size(), 0u);
    for (size_t i = 0; i < plan.edges.size(); ++i) plan.borrows[plan.edges[i].pixel] = 1u;
    for (size_t i = 0; i < plan.edges.size(); ++i)
      if (plan.from[i] < 0) plan.borrows[plan.edges[i].pixel] = 0u;
    for (size_t p = 0; p < plan.gathers.size(); ++p)
      if (plan.borrows[p]) {
        plan.gathers[p] = 0u;
        ++plan.borrowing;
      }
    return plan;
  }

  /// The deferred gathers of the pixels `plan` says gather, in tile order, added to the
  /// filter's buffer; the filter's statistics into `result`.
  void runPlannedGathers(const GatherPlan& plan, RenderResult& result) {
    std::vector<PendingGather> pending;
    for (std::vector<PendingGather>& t : m_tilePending) {
      for (const PendingGather& g : t)
        if (plan.gathers[g.pixel]) pending.push_back(g);
      std::vector<PendingGather>().swap(t);
    }
    uint64_t filterable = 0, gathering = 0;
    for (size_t p = 0; p < plan.gathers.size(); ++p) {
      filterable += m_ib.filterable[p];
      gathering += plan.gathers[p];
    }
    const uint64_t gathersRun = pending.size();
    result.filterStats = {{"filterable", filterable}, {"gathering", gathering}, {"unfilled", plan.unfilled},
                          {"borrowing", plan.borrowing}, {"gathers", gathersRun}};
    uint64_t bad = 0;
    runGathers(m_gather, pending, m_settings.spp, m_ib, bad, m_progress);
    m_invalid += bad;
  }

  /// The filtered indirect light (borrowed where `plan` says so) added to the film's image,
  /// and to its Indirect layer; both into `result`.
  void filter(const GatherPlan& plan, RenderResult& result) const {
    std::vector<Vec3> indirect = filterIndirect(m_ib, m_filterRadius);
    // The borrowing pixels: each sample's share of its filter pixel's light, in sample order.
    std::vector<DVec3> borrowed(indirect.size(), DVec3(0.0));
    for (size_t i = 0; i < plan.edges.size(); ++i)
      if (plan.borrows[plan.edges[i].pixel])
        borrowed[plan.edges[i].pixel] += DVec3(indirect[size_t(plan.from[i])] * plan.edges[i].albedo);
    for (size_t p = 0; p < indirect.size(); ++p)
      indirect[p] = plan.borrows[p] ? Vec3(borrowed[p] / double(m_settings.spp)) : indirect[p] * m_modulation[p];
    result.image = m_film.image(m_settings.spp);
    for (size_t p = 0; p < indirect.size(); ++p) result.image.pixels[p] += indirect[p];
    result.layers = m_film.layers(m_settings.spp);
    // The Indirect layer holds the filtered light, as the image does.
    for (ImageLayer& l : result.layers)
      if (l.name == aovNames()[size_t(Aov::Indirect)])
        for (size_t p = 0; p < indirect.size(); ++p)
          for (int c = 0; c < 3; ++c) l.values[p * 3 + size_t(c)] += indirect[p][c];
  }

  const Scene& m_scene;
  const Integrator& m_integrator;
  const ScreenSpaceGather& m_gather;
  const RenderSettings& m_settings;
  Progress* m_progress;
  const int m_filterRadius;
  const int m_w, m_h, m_tilesX, m_tilesY;
  Film m_film;
  const AovSampler m_aovs;
  GlintPlan m_glints;
  IndirectBuffer m_ib;
  std::vector<Vec3> m_modulation;  ///< per pixel, the mean IndirectSplit::albedo of its samples: the filtered light's factor
  float m_pixelAngle = 0.0f;       ///< world-space width of a pixel per unit distance from the camera
  std::vector<std::vector<PendingGather>> m_tilePending;  ///< per tile, the gathers its samples deferred
  std::vector<std::vector<EdgeSample>> m_tileEdges;      ///< per tile, its edge samples
  std::atomic<uint64_t> m_invalid{0};
};

}  // namespace

Vec3 Integrator::liTerms(const Ray&, Sampler&, IndirectSplit*, RadianceTerms&) const {
  throw Error(name() + " does not separate its terms");
}

RenderResult renderImage(const Scene& scene, const Integrator& integrator, const RenderSettings& settings,
                         Progress* progress, bool keepPartial, const AovRequest* aovRequest) {
  settings.validate();
  if (aovRequest && aovRequest->layers.empty()) aovRequest = nullptr;
  if (aovRequest) {
    if (!aovRequest->accel) throw Error("renderImage: AOVs without an accelerator");
    checkAovs(integrator, aovRequest->layers);
  }
  const ScreenSpaceGather* gather = integrator.screenSpaceGather();
  if (!gather || gather->indirectFilterRadius() <= 0)
    return renderPasses(scene, integrator, settings, progress, keepPartial, aovRequest);
  return FilteredRender(scene, integrator, *gather, settings, progress, aovRequest).run();
}

std::vector<PixelSamples> renderPixels(const Scene& scene, const Integrator& integrator, const RenderSettings& settings,
                                       const std::vector<size_t>& pixels) {
  std::vector<PixelSamples> out(pixels.size());
  const int w = settings.width, h = settings.height;
  tbb::parallel_for(size_t(0), pixels.size(), [&](size_t i) {
    const size_t pixel = pixels[i];
    const int x = int(pixel % size_t(w)), y = int(pixel / size_t(w));
    Sampler sampler(settings.sampler, settings.seed, pixel, uint32_t(settings.spp));
    PixelSamples& p = out[i];
    for (int s = 0; s < settings.spp; ++s) {
      sampler.startSample(uint32_t(s));
      const Vec2 jitter = sampler.uniform2();
      const Ray ray = scene.camera.generateRay(float(x) + jitter.x, float(y) + jitter.y, w, h);
      const Vec3 L = integrator.li(ray, sampler);
      if (!usableRadiance(L)) continue;
      p.sum += DVec3(L);
      p.sumSquares += DVec3(L) * DVec3(L);
      ++p.count;
    }
  });
  return out;
}

}  // namespace voxcone
