#include "voxcone/accel/accel.h"
#include "voxcone/core/error.h"
#include "voxcone/core/rng.h"
#include "voxcone/core/timer.h"
#include "voxcone/integrator/indirect_filter.h"
#include "voxcone/integrator/integrator.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>

namespace voxcone {

namespace {
/// Pixels whose samples' first-hit normals differ by more than this (8 degrees) saw more than
/// one surface (an edge or a crease inside the pixel): their indirect light is not filtered.
/// Measured (256x256 defaults): 0.9 instead leaves cornell-box at 38.28 dB (38.27) and lifts
/// cornell-dragon from 39.00 to 39.32 dB, since most of the dragon's pixels span facets a few
/// degrees apart; the stricter value is kept until the studies are re-run with it.
constexpr float kSameSurfaceCos = 0.99f;

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
/// (onFilterSurface) whose point it sees along the surface (Integrator::linkedPoints), or -1.
/// Offsets are tried by distance, then row, then column: deterministic.
std::vector<int64_t> borrowFrom(const Integrator& integrator, const IndirectBuffer& ib,
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
      if (!integrator.linkedPoints(e.position + e.normal * lift, ib.position[q] + ib.normal[q] * lift)) continue;
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
void runGathers(const Integrator& integrator, const std::vector<PendingGather>& pending, int spp, IndirectBuffer& ib,
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
      value[i] = pending[i].gather.weight * integrator.gatherDeferred(pending[i].gather);
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

/// Per-pixel sums of the AOV layers' channels (double, pixel-major, the layers in the order
/// asked), one sample at a time, from the sample's camera ray and its RadianceTerms.
class AovSums {
public:
  AovSums(const Scene& scene, const AovRequest* request, size_t pixels) : m_scene(scene) {
    if (!request) return;
    m_request = request;
    for (Aov a : request->layers) {
      m_offsets.push_back(m_channels);
      m_channels += aovChannels(a).size();
      m_firstHit = m_firstHit || !isTermAov(a);
      m_terms = m_terms || isTermAov(a);
    }
    sums.assign(pixels * m_channels, 0.0);
  }
  bool active() const { return m_channels > 0; }
  /// Whether a term layer is asked for (samples then go through liTerms).
  bool terms() const { return m_terms; }

  /// Add one sample of `pixel`.
  void add(size_t pixel, const Ray& ray, const RadianceTerms& t) {
    SurfaceHit sh;
    const bool hit = m_firstHit && intersectSurface(m_scene, *m_request->accel, ray, sh);
    double* out = &sums[pixel * m_channels];
    for (size_t i = 0; i < m_request->layers.size(); ++i) {
      double* o = out + m_offsets[i];
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

  /// Add `v` to `pixel`'s sums of layer `a`, where it is asked for.
  void addTo(size_t pixel, Aov a, const DVec3& v) {
    if (!active()) return;
    for (size_t i = 0; i < m_request->layers.size(); ++i)
      if (m_request->layers[i] == a)
        for (int c = 0; c < 3; ++c) sums[pixel * m_channels + m_offsets[i] + size_t(c)] += v[c];
  }

  /// The layers: each sum over `spp` samples; `filtered`, when given, is each pixel's filtered
  /// indirect light, added to the Indirect layer as renderImage adds it to the beauty.
  std::vector<ImageLayer> layers(int spp, const std::vector<Vec3>* filtered = nullptr) const {
    std::vector<ImageLayer> out;
    if (!active()) return out;
    const size_t pixels = sums.size() / m_channels;
    for (size_t i = 0; i < m_request->layers.size(); ++i) {
      const Aov a = m_request->layers[i];
      ImageLayer l{aovNames()[size_t(a)], aovChannels(a), {}};
      const size_t nc = l.channels.size();
      l.values.resize(pixels * nc);
      for (size_t p = 0; p < pixels; ++p)
        for (size_t c = 0; c < nc; ++c) {
          float v = float(sums[p * m_channels + m_offsets[i] + c] / double(spp));
          if (a == Aov::Indirect && filtered) v += (*filtered)[p][int(c)];
          l.values[p * nc + c] = v;
        }
      out.push_back(std::move(l));
    }
    return out;
  }

  std::vector<double> sums;

private:
  const Scene& m_scene;
  const AovRequest* m_request = nullptr;
  std::vector<size_t> m_offsets;
  size_t m_channels = 0;
  bool m_firstHit = false, m_terms = false;
};

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

/// One sample's radiance: li, or with AOVs liTerms, whose terms and first hit go into `aovs`
/// when the estimate is usable; without its glints where `glints` (glintSum takes them).
Vec3 takeSample(const Integrator& integrator, const Ray& ray, Sampler& sampler, size_t pixel, AovSums& aovs,
                bool glints) {
  if (!aovs.active() && !glints) return integrator.li(ray, sampler);
  RadianceTerms terms;
  Vec3 L = aovs.terms() || glints ? integrator.liTerms(ray, sampler, nullptr, terms) : integrator.li(ray, sampler);
  if (glints) leaveOutGlints(L, terms);
  if (usableRadiance(L) && aovs.active()) aovs.add(pixel, ray, terms);
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
/// sums its samples in sample order into one double sum whatever the passes, so the image is
/// the one a single pass gives, bit for bit. Cancellation is checked at every pixel of every
/// pass (a pixel's share of a pass is at most 64 samples: milliseconds), so a render stops
/// within a fraction of a second at any spp; with keepPartial it then returns the passes that
/// completed as an image of fewer samples (RenderResult::partial), else throws CancelledError.
RenderResult renderPasses(const Scene& scene, const Integrator& integrator, const RenderSettings& settings,
                          Progress* progress, bool keepPartial, const AovRequest* aovRequest) {
  constexpr int kTile = 16;
  const int w = settings.width, h = settings.height;
  const int tilesX = (w + kTile - 1) / kTile, tilesY = (h + kTile - 1) / kTile;
  const size_t n = size_t(w) * size_t(h);
  std::vector<DVec3> sum(n, DVec3(0.0)), complete;  // complete: the sums after the last whole pass
  AovSums aovs(scene, aovRequest, n);
  std::vector<double> aovComplete;
  std::atomic<uint64_t> invalid{0};
  uint64_t invalidComplete = 0;
  std::atomic<bool> cancelled{false};
  const std::vector<int> passes = passSizes(settings.spp);
  Timer timer;
  const int glintPerSample = integrator.glintSamples();
  const std::vector<uint8_t> glintPixel =
      glintPerSample > 0 ? glintPixels(scene, integrator, w, h) : std::vector<uint8_t>();
  if (progress) progress->start("render", uint64_t(tilesX) * uint64_t(tilesY) * passes.size());
  int doneSpp = 0;
  for (const int passSpp : passes) {
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
          const size_t pixel = size_t(y) * size_t(w) + size_t(x);
          Sampler sampler(settings.sampler, settings.seed, pixel, static_cast<uint32_t>(settings.spp));
          const bool glints = !glintPixel.empty() && glintPixel[pixel];
          for (int s = doneSpp; s < doneSpp + passSpp; ++s) {
            sampler.startSample(static_cast<uint32_t>(s));
            const Vec2 jitter = sampler.uniform2();
            const Ray ray = scene.camera.generateRay(float(x) + jitter.x, float(y) + jitter.y, w, h);
            const Vec3 L = takeSample(integrator, ray, sampler, pixel, aovs, glints);
            if (!usableRadiance(L)) ++bad;
            else sum[pixel] += DVec3(L);
          }
          if (glints) {
            const DVec3 g = glintSum(scene, integrator, settings, x, y, glintPerSample, doneSpp, passSpp, bad);
            sum[pixel] += g;
            aovs.addTo(pixel, Aov::Emitted, g);
          }
        }
      invalid += bad;
      if (progress) progress->advance(1);
    });
    if (cancelled) break;
    doneSpp += passSpp;
    if (keepPartial && doneSpp < settings.spp) {
      complete = sum;
      aovComplete = aovs.sums;
      invalidComplete = invalid;
    }
  }
  RenderResult result;
  result.image = Image(w, h);
  result.completedSpp = doneSpp;
  if (cancelled) {
    if (!keepPartial || doneSpp == 0) throw CancelledError();
    sum.swap(complete);
    aovs.sums.swap(aovComplete);
    invalid = invalidComplete;
    result.partial = true;
  }
  if (progress) progress->finish();
  for (size_t p = 0; p < n; ++p) result.image.pixels[p] = Vec3(sum[p] / double(doneSpp));
  result.layers = aovs.layers(doneSpp);
  result.stageSeconds["samples"] = timer.seconds();
  result.seconds = timer.seconds();
  result.samples = uint64_t(n) * uint64_t(doneSpp);
  result.invalidSamples = invalid;
  return result;
}
}  // namespace

void Integrator::linkIndirect(IndirectBuffer& buffer) const { buffer.link.assign(buffer.indirect.size(), 0u); }

Vec3 Integrator::liTerms(const Ray&, Sampler&, IndirectSplit*, RadianceTerms&) const {
  throw Error(name() + " does not separate its terms");
}

const std::vector<std::string>& aovNames() {
  static const std::vector<std::string> names = {"albedo", "normal", "depth", "emitted", "direct", "indirect", "caustic"};
  return names;
}

std::vector<Aov> parseAovs(const std::string& list) {
  std::vector<Aov> out;
  size_t start = 0;
  while (start <= list.size()) {
    const size_t end = std::min(list.find(',', start), list.size());
    const std::string name = list.substr(start, end - start);
    const auto& names = aovNames();
    const auto it = std::find(names.begin(), names.end(), name);
    if (it == names.end()) {
      std::string known;
      for (const std::string& n : names) known += (known.empty() ? "" : ", ") + n;
      throw SettingsError("--aov: unknown layer '" + name + "' (known: " + known + ")");
    }
    const Aov a = Aov(it - names.begin());
    if (std::find(out.begin(), out.end(), a) != out.end()) throw SettingsError("--aov: " + name + " given twice");
    out.push_back(a);
    start = end + 1;
  }
  return out;
}

std::vector<std::string> aovChannels(Aov aov) {
  const auto rgb = [](const std::string& layer) {
    return std::vector<std::string>{layer + ".R", layer + ".G", layer + ".B"};
  };
  switch (aov) {
    case Aov::Albedo: return rgb("Albedo");
    case Aov::Normal: return {"Ns.X", "Ns.Y", "Ns.Z"};
    case Aov::Depth: return {"Z"};
    case Aov::Emitted: return rgb("Emitted");
    case Aov::Direct: return rgb("Direct");
    case Aov::Indirect: return rgb("Indirect");
    case Aov::Caustic: return rgb("Caustic");
  }
  return {};
}

bool isTermAov(Aov aov) { return aov != Aov::Albedo && aov != Aov::Normal && aov != Aov::Depth; }

void checkAovs(const Integrator& integrator, const std::vector<Aov>& layers) {
  if (integrator.separatesTerms()) return;
  for (Aov a : layers)
    if (isTermAov(a))
      throw SettingsError("--aov " + aovNames()[size_t(a)] + ": method " + integrator.name() +
                          " does not separate its terms (path, whitted and voxcone do)");
}

RenderResult renderImage(const Scene& scene, const Integrator& integrator, const RenderSettings& settings,
                         Progress* progress, bool keepPartial, const AovRequest* aovRequest) {
  settings.validate();
  if (aovRequest && aovRequest->layers.empty()) aovRequest = nullptr;
  if (aovRequest) {
    if (!aovRequest->accel) throw Error("renderImage: AOVs without an accelerator");
    checkAovs(integrator, aovRequest->layers);
  }
  const int filterRadius = integrator.indirectFilterRadius();
  const bool split = filterRadius > 0;
  if (!split) return renderPasses(scene, integrator, settings, progress, keepPartial, aovRequest);
  constexpr int kTile = 16;
  const int w = settings.width, h = settings.height;
  const int tilesX = (w + kTile - 1) / kTile, tilesY = (h + kTile - 1) / kTile;
  RenderResult result;
  result.completedSpp = settings.spp;
  result.image = Image(w, h);
  IndirectBuffer ib;
  // Per pixel, the mean IndirectSplit::albedo of its samples: the filtered light's factor.
  std::vector<Vec3> modulation;
  if (split) {
    const size_t n = size_t(w) * size_t(h);
    modulation.assign(n, Vec3(1.0f));
    ib.width = w;
    ib.height = h;
    ib.indirect.assign(n, Vec3(0.0f));
    ib.position.assign(n, Vec3(0.0f));
    ib.normal.assign(n, Vec3(0.0f));
    ib.material.assign(n, 0u);
    ib.footprint.assign(n, 0.0f);
    ib.filterable.assign(n, 0u);
  }
  // World-space width of a pixel per unit distance from the camera.
  const float pixelAngle = 2.0f * std::tan(0.5f * scene.camera.fovYDeg() * kPi / 180.0f) / float(h);
  std::vector<std::vector<PendingGather>> tilePending(size_t(tilesX) * size_t(tilesY));
  std::vector<std::vector<EdgeSample>> tileEdges(tilePending.size());
  std::atomic<uint64_t> invalid{0};
  std::atomic<bool> cancelled{false};
  AovSums aovs(scene, aovRequest, size_t(w) * size_t(h));
  Timer timer;
  const int glintPerSample = integrator.glintSamples();
  const std::vector<uint8_t> glintPixel =
      glintPerSample > 0 ? glintPixels(scene, integrator, w, h) : std::vector<uint8_t>();
  if (glintPerSample > 0) result.stageSeconds["glint_probe"] = timer.seconds();
  if (progress) progress->start("render", static_cast<uint64_t>(tilesX) * tilesY);
  tbb::parallel_for(0, tilesX * tilesY, [&](int tile) {
    if (cancelled.load(std::memory_order_relaxed)) return;
    if (progress && progress->cancelled()) {
      cancelled = true;
      return;
    }
    const int x0 = (tile % tilesX) * kTile, y0 = (tile / tilesX) * kTile;
    uint64_t bad = 0;
    std::vector<EdgeSample> pixelSamples;
    for (int y = y0; y < std::min(y0 + kTile, h); ++y)
      for (int x = x0; x < std::min(x0 + kTile, w); ++x) {
        // Checked at every pixel: a tile of many samples per pixel is seconds of work.
        if (progress && progress->cancelled()) {
          cancelled = true;
          return;
        }
        const size_t pixel = static_cast<size_t>(y) * static_cast<size_t>(w) + static_cast<size_t>(x);
        Sampler sampler(settings.sampler, settings.seed, pixel, static_cast<uint32_t>(settings.spp));
        // Sum in double so the mean does not depend on float rounding of a long sum.
        DVec3 sum(0.0), indirectSum(0.0), positionSum(0.0), albedoSum(0.0);
        int seen = 0;  // samples whose first hit split off its indirect light
        bool oneSurface = true;
        IndirectSplit first;
        pixelSamples.clear();
        // Glints from the glint samples: the camera samples leave theirs out.
        const bool glints = !glintPixel.empty() && glintPixel[pixel];
        for (int s = 0; s < settings.spp; ++s) {
          sampler.startSample(static_cast<uint32_t>(s));
          const Vec2 jitter = sampler.uniform2();
          const Ray ray = scene.camera.generateRay(static_cast<float>(x) + jitter.x, static_cast<float>(y) + jitter.y, w, h);
          IndirectSplit sp;
          RadianceTerms terms;
          Vec3 L = aovs.terms() || glints ? integrator.liTerms(ray, sampler, &sp, terms)
                                          : integrator.liSplit(ray, sampler, sp);
          if (glints) leaveOutGlints(L, terms);
          if (!usableRadiance(L) || (sp.valid && !usableRadiance(sp.indirect))) {
            ++bad;
            oneSurface = false;
            continue;
          }
          if (aovs.active()) aovs.add(pixel, ray, terms);
          sum += DVec3(L);
          if (!sp.valid) {
            oneSurface = false;
            continue;
          }
          if (sp.deferred) tilePending[size_t(tile)].push_back({pixel, sp.gather});
          else indirectSum += DVec3(sp.indirect);
          positionSum += DVec3(sp.position);
          albedoSum += DVec3(sp.albedo);
          pixelSamples.push_back({pixel, sp.position, sp.normal, sp.material, sp.albedo});
          if (seen++ == 0) first = sp;
          else if (sp.material != first.material || glm::dot(sp.normal, first.normal) < kSameSurfaceCos) oneSurface = false;
        }
        if (glints) {
          const DVec3 g = glintSum(scene, integrator, settings, x, y, glintPerSample, 0, settings.spp, bad);
          sum += g;
          aovs.addTo(pixel, Aov::Emitted, g);
        }
        const DVec3 spp(settings.spp);
        // With the filter: all but the split-off indirect light now, that after the filter.
        result.image.at(x, y) = Vec3(sum / spp);
        if (!split) continue;
        ib.indirect[pixel] = Vec3(indirectSum / spp);
        if (seen > 0) modulation[pixel] = Vec3(albedoSum / double(seen));
        if (seen > 0 && oneSurface) {
          ib.position[pixel] = Vec3(positionSum / double(seen));
          ib.normal[pixel] = first.normal;
          ib.material[pixel] = first.material;
          ib.footprint[pixel] = std::max(1e-30f, pixelAngle * glm::length(ib.position[pixel] - scene.camera.position()));
          ib.filterable[pixel] = 1u;
        } else if (seen > 0) {
          tileEdges[size_t(tile)].insert(tileEdges[size_t(tile)].end(), pixelSamples.begin(), pixelSamples.end());
        }
      }
    invalid += bad;
    if (progress) progress->advance(1);
  });
  if (cancelled) throw CancelledError();
  if (progress) progress->finish();
  result.stageSeconds["samples"] = timer.seconds();
  if (split) {
    Timer stage;
    // Which pixels run their deferred gathers: one per block on the filter's surfaces, every
    // pixel off them (the filter keeps those as they are), and any the filter cannot fill.
    const int spacing = std::max(1, integrator.gatherSpacing());
    std::vector<uint8_t> gathers(size_t(w) * size_t(h), 1u);
    ib.estimated.assign(gathers.size(), 1u);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const size_t p = size_t(y) * size_t(w) + size_t(x);
        if (ib.filterable[p] && !gathersInBlock(x, y, spacing, settings.seed)) gathers[p] = ib.estimated[p] = 0u;
      }
    integrator.linkIndirect(ib);
    uint64_t unfilledCount = 0;
    if (spacing > 1) {
      const std::vector<uint8_t> unfilled = unfilledPixels(ib, filterRadius);
      for (size_t p = 0; p < unfilled.size(); ++p)
        if (unfilled[p]) {
          gathers[p] = ib.estimated[p] = 1u;
          ++unfilledCount;
        }
    }
    // Pixels the filter does not take: where each of their samples on a filterable surface
    // finds a filter pixel of that surface nearby, the sample takes that pixel's filtered light
    // and the pixel gathers nothing; any sample without one and the pixel gathers as before.
    std::vector<EdgeSample> edges;
    for (const std::vector<EdgeSample>& t : tileEdges) edges.insert(edges.end(), t.begin(), t.end());
    tileEdges = {};
    const std::vector<int64_t> from = borrowFrom(integrator, ib, edges);
    std::vector<uint8_t> borrows(gathers.size(), 0u);
    for (size_t i = 0; i < edges.size(); ++i) borrows[edges[i].pixel] = 1u;
    for (size_t i = 0; i < edges.size(); ++i)
      if (from[i] < 0) borrows[edges[i].pixel] = 0u;
    uint64_t borrowing = 0;
    for (size_t p = 0; p < gathers.size(); ++p)
      if (borrows[p]) {
        gathers[p] = 0u;
        ++borrowing;
      }
    result.stageSeconds["link"] = stage.seconds();
    stage.reset();
    // The gathers to run, in tile order.
    std::vector<PendingGather> pending;
    for (std::vector<PendingGather>& t : tilePending) {
      for (const PendingGather& g : t)
        if (gathers[g.pixel]) pending.push_back(g);
      std::vector<PendingGather>().swap(t);
    }
    uint64_t filterable = 0, gathering = 0;
    for (size_t p = 0; p < gathers.size(); ++p) {
      filterable += ib.filterable[p];
      gathering += gathers[p];
    }
    const uint64_t gathersRun = pending.size();
    result.filterStats = {{"filterable", filterable}, {"gathering", gathering}, {"unfilled", unfilledCount},
                          {"borrowing", borrowing}, {"gathers", gathersRun}};
    uint64_t bad = 0;
    runGathers(integrator, pending, settings.spp, ib, bad, progress);
    invalid += bad;
    result.stageSeconds["gather"] = stage.seconds();
    stage.reset();
    std::vector<Vec3> indirect = filterIndirect(ib, filterRadius);
    // The borrowing pixels: each sample's share of its filter pixel's light, in sample order.
    std::vector<DVec3> borrowed(indirect.size(), DVec3(0.0));
    for (size_t i = 0; i < edges.size(); ++i)
      if (borrows[edges[i].pixel]) borrowed[edges[i].pixel] += DVec3(indirect[size_t(from[i])] * edges[i].albedo);
    for (size_t p = 0; p < indirect.size(); ++p)
      indirect[p] = borrows[p] ? Vec3(borrowed[p] / double(settings.spp)) : indirect[p] * modulation[p];
    for (size_t p = 0; p < indirect.size(); ++p) result.image.pixels[p] += indirect[p];
    result.layers = aovs.layers(settings.spp, &indirect);
    result.stageSeconds["filter"] = stage.seconds();
  }
  result.seconds = timer.seconds();
  result.samples = static_cast<uint64_t>(w) * h * settings.spp;
  result.invalidSamples = invalid;
  return result;
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
