// The pilot pass of `render --target-error / --time-budget` (auto_settings.h).

#include "voxcone/integrator/auto_settings.h"

#include "voxcone/core/error.h"
#include "voxcone/core/timer.h"
#include "voxcone/image/metrics.h"
#include "voxcone/integrator/integrator.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>

namespace voxcone {

namespace {

constexpr int kPilotSpp = 4;
constexpr uint64_t kPilotPhotons = 100000;  ///< P0; the second photon pilot has 4 P0
constexpr int kFinestLevel = 8;             ///< taken as converged in level
const int kLevels[] = {5, 6, 7, 8};
const int kCones[] = {6, 16};
const uint64_t kPhotons[] = {10000, 25000, 50000, 100000, 250000, 500000, 1000000, 2000000};

struct Pilot {
  Image image;
  double prepareSeconds = 0.0, renderSeconds = 0.0;
};

/// One pilot render: voxcone with `options` at the pilot settings.
Pilot runPilot(const Scene& scene, const Accel& accel, const RenderSettings& pilotSettings, uint64_t pixelSeed,
               const nlohmann::json& options) {
  RenderSettings s = pilotSettings;
  s.seed = pixelSeed;
  IntegratorContext ctx{scene, accel, s, options};
  std::unique_ptr<Integrator> integrator = createIntegrator("voxcone", ctx);
  Pilot p;
  Timer t;
  integrator->prepare(nullptr);
  p.prepareSeconds = t.seconds();
  RenderResult r = renderImage(scene, *integrator, s);
  p.renderSeconds = r.seconds;
  p.image = std::move(r.image);
  return p;
}

std::string fmt(const char* f, double v) {
  char b[64];
  std::snprintf(b, sizeof b, f, v);
  return b;
}

}  // namespace

AutoSettingsResult chooseVoxconeSettings(const Scene& scene, const Accel& accel, const RenderSettings& settings,
                                         const AutoSettingsRequest& req, Progress* progress) {
  const bool byError = req.targetRelMse > 0.0, byTime = req.timeBudget > 0.0;
  if (byError == byTime) throw SettingsError("give one of --target-error and --time-budget, with a positive value");
  if (!req.fixedOptions.is_object()) throw SettingsError("voxcone options must be a JSON object");
  Timer pilotTimer;
  // The pilot's model (render time and pixel noise per sample) is of cones on every sample.
  nlohmann::json fixed = req.fixedOptions;
  if (!fixed.contains("gathers")) fixed["gathers"] = 0;
  for (const char* k : {"level", "photons", "cones"})
    if (fixed.contains(k) && !fixed[k].is_number_integer())
      throw SettingsError(std::string("voxcone.") + k + ": expected an integer");

  // Pilot settings: a quarter of the resolution per axis (at least 16 pixels), 4 spp.
  RenderSettings ps = settings;
  ps.width = std::max(16, settings.width / 4);
  ps.height = std::max(16, settings.height / 4);
  ps.spp = kPilotSpp;
  const double causticRatio = settings.photons > 0 && settings.causticPhotons > 0
                                  ? double(settings.causticPhotons) / double(settings.photons)
                                  : 0.2;
  // The user's other options (kernel, exact_segment, ...) apply to every pilot.
  nlohmann::json base = fixed;
  for (const char* k : {"level", "photons", "caustic_photons", "cones", "seed"}) base.erase(k);
  auto opts = [&](int level, uint64_t photons, int cones, int photonSeed) {
    nlohmann::json o = base;
    o["level"] = level;
    o["photons"] = photons;
    o["caustic_photons"] = uint64_t(std::llround(double(photons) * causticRatio));
    o["cones"] = cones;
    o["seed"] = photonSeed;
    return o;
  };
  const uint64_t s = settings.seed, p0 = kPilotPhotons, p1 = 4 * kPilotPhotons;
  if (progress) progress->start("pilot", 8);
  auto pilot = [&](uint64_t pixelSeed, const nlohmann::json& o) {
    Pilot p = runPilot(scene, accel, ps, pixelSeed, o);
    if (progress) progress->advance(1);
    return p;
  };
  // Photon seed = pixel seed + option seed: A and B share their photons, A and P their pixels.
  const Pilot A = pilot(s, opts(7, p0, 6, 1));
  // Pixel noise at the full resolution (1 spp): a coarser pixel averages more of the image's
  // edges and texture and is noisier per sample.
  RenderSettings full = settings;
  full.spp = 1;
  const Pilot noiseA = runPilot(scene, accel, full, s, opts(7, p0, 6, 1));
  const Pilot noiseB = runPilot(scene, accel, full, s + 1, opts(7, p0, 6, 0));
  if (progress) progress->advance(1);
  const Pilot P = pilot(s, opts(7, p1, 6, 2));
  std::map<int, Pilot> levels;
  for (int l : {5, 6, 8}) levels[l] = pilot(s, opts(l, p0, 6, 1));
  levels[7] = A;
  const Pilot C16 = pilot(s, opts(7, p0, 16, 1));
  if (progress) progress->finish();

  // The error terms (relMSE of a difference of two independent estimates is twice the variance
  // term of one).
  const double a = std::max(0.0, relMseOfEstimates(noiseA.image, noiseB.image) / 2.0);
  const double b = std::max(0.0, relMseOfEstimates(A.image, P.image) / (1.0 / double(p0) + 1.0 / double(p1)));
  std::map<int, double> levelBias;
  for (int l : kLevels) levelBias[l] = l == kFinestLevel ? 0.0 : relMseOfEstimates(levels[l].image, levels[kFinestLevel].image);
  const double coneBias6 = relMseOfEstimates(A.image, C16.image);
  std::map<int, double> coneBias = {{6, coneBias6}, {16, 0.0}};
  // Time terms.
  const double pilotSamples = double(ps.width) * ps.height * kPilotSpp;
  const double perPhoton = std::max(0.0, (P.prepareSeconds - A.prepareSeconds) / double(p1 - p0));
  const double coneFactor = A.renderSeconds > 0.0 ? C16.renderSeconds / A.renderSeconds : 16.0 / 6.0;
  const double pilotSeconds = pilotTimer.seconds();

  auto fixedInt = [&](const char* k) { return fixed.contains(k) ? fixed[k].get<int64_t>() : int64_t(0); };
  std::vector<int> levelChoices, coneChoices;
  std::vector<uint64_t> photonChoices;
  std::vector<int> sppChoices;
  if (fixedInt("level") > 0) levelChoices = {int(fixedInt("level"))};
  else levelChoices.assign(std::begin(kLevels), std::end(kLevels));
  if (fixedInt("cones") > 0) coneChoices = {int(fixedInt("cones"))};
  else coneChoices.assign(std::begin(kCones), std::end(kCones));
  if (fixed.contains("photons")) photonChoices = {uint64_t(std::max<int64_t>(0, fixedInt("photons")))};
  else photonChoices.assign(std::begin(kPhotons), std::end(kPhotons));
  if (req.fixedSpp > 0) sppChoices = {req.fixedSpp};
  else
    for (int spp = 1; spp <= 4096; spp *= 2) sppChoices.push_back(spp);

  struct Candidate {
    int level, cones, spp;
    uint64_t photons;
    double pixelNoise, photonNoise, levelBias, coneBias, seconds;
    double error() const { return pixelNoise + photonNoise + levelBias + coneBias; }
  };
  // A level or cone count the pilot did not render is predicted from the nearest it did.
  auto nearestLevel = [&](int l) { return std::clamp(l, 5, 8); };
  // Other cone counts (given by the user): linear in the count between and beyond 6 and 16.
  auto biasOfCones = [&](int c) { return std::max(0.0, coneBias6 * (16.0 - c) / 10.0); };
  auto coneTime = [&](int c) { return std::max(0.1, 1.0 + (coneFactor - 1.0) * (c - 6) / 10.0); };
  std::vector<Candidate> all;
  for (int l : levelChoices)
    for (int c : coneChoices)
      for (uint64_t ph : photonChoices)
        for (int spp : sppChoices) {
          const Pilot& lp = levels[nearestLevel(l)];
          const double prepare = std::max(0.0, lp.prepareSeconds + perPhoton * (double(ph) - double(p0)));
          const double render =
              lp.renderSeconds / pilotSamples * double(settings.width) * settings.height * spp * coneTime(c);
          all.push_back({l, c, spp, ph, a / spp, ph > 0 ? b / double(ph) : 1.0, levelBias[nearestLevel(l)],
                         biasOfCones(c), prepare + render});
        }
  // Fastest meeting the target, or most accurate within the budget (the pilot's time spent);
  // when none does, the most accurate (target) or the fastest (budget).
  auto meets = [&](const Candidate& c) {
    return byError ? c.error() <= req.targetRelMse : c.seconds <= req.timeBudget - pilotSeconds;
  };
  auto rank = [&](const Candidate& c) {
    const bool ok = meets(c);
    return std::make_pair(!ok, byError == ok ? c.seconds : c.error());
  };
  const Candidate* best = &*std::min_element(all.begin(), all.end(),
                                             [&](const Candidate& x, const Candidate& y) { return rank(x) < rank(y); });
  const bool met = meets(*best);
  AutoSettingsResult r;
  r.options = fixed;
  r.options["level"] = best->level;
  r.options["photons"] = best->photons;
  if (!fixed.contains("caustic_photons"))
    r.options["caustic_photons"] = uint64_t(std::llround(double(best->photons) * causticRatio));
  r.options["cones"] = best->cones;
  r.spp = best->spp;
  r.predictedRelMse = best->error();
  r.predictedSeconds = best->seconds;
  r.pilotSeconds = pilotSeconds;
  r.met = met;
  const double noise = best->pixelNoise, photonNoise = best->photonNoise, lb = best->levelBias, cb = best->coneBias;
  nlohmann::json levelJson = nlohmann::json::object();
  for (const auto& [l, v] : levelBias) levelJson[std::to_string(l)] = v;
  r.report = {{"target_relmse", byError ? nlohmann::json(req.targetRelMse) : nlohmann::json()},
              {"time_budget_seconds", byTime ? nlohmann::json(req.timeBudget) : nlohmann::json()},
              {"met", met},
              {"chosen", {{"level", best->level}, {"photons", best->photons}, {"cones", best->cones}, {"spp", best->spp}}},
              {"predicted_relmse", best->error()},
              {"predicted_terms", {{"pixel_noise", noise}, {"photon_noise", photonNoise}, {"level_bias", lb}, {"cone_bias", cb}}},
              {"predicted_seconds", best->seconds},
              {"pilot",
               {{"width", ps.width}, {"height", ps.height}, {"spp", kPilotSpp}, {"seconds", pilotSeconds},
                {"pixel_noise_per_sample", a}, {"photon_noise_times_photons", b}, {"level_bias", levelJson},
                {"cone_bias_6_vs_16", coneBias6}, {"prepare_seconds_per_photon", perPhoton},
                {"render_seconds_per_sample_level7", A.renderSeconds / pilotSamples}, {"cone_time_factor_16_vs_6", coneFactor}}},
              {"candidates", all.size()}};
  r.summary = std::string(met ? "chose" : (byError ? "no setting meets the target; closest:" : "nothing fits the budget; fastest:")) +
              " level " + std::to_string(best->level) + ", " + std::to_string(best->photons) + " photons, " +
              std::to_string(best->cones) + " cones, " + std::to_string(best->spp) + " spp\n" +
              "  predicted relMSE " + fmt("%.4g", best->error()) + " = pixel noise " + fmt("%.3g", noise) +
              " + photon noise " + fmt("%.3g", photonNoise) + " + level bias " + fmt("%.3g", lb) + " + cone bias " +
              fmt("%.3g", cb) + (byError ? " (target " + fmt("%.4g", req.targetRelMse) + ")" : std::string()) + "\n" +
              "  predicted time " + fmt("%.2f", best->seconds) + " s" +
              (byTime ? " (budget " + fmt("%.2f", req.timeBudget) + " s, pilot " + fmt("%.2f", pilotSeconds) + " s of it)"
                      : " (pilot " + fmt("%.2f", pilotSeconds) + " s)") +
              "\n  from a " + std::to_string(ps.width) + "x" + std::to_string(ps.height) +
              " pilot: level bias 5/6/7 " + fmt("%.3g", levelBias[5]) + "/" + fmt("%.3g", levelBias[6]) + "/" +
              fmt("%.3g", levelBias[7]) + " (against level 8), cone bias 6 vs 16 " + fmt("%.3g", coneBias6) + "\n";
  return r;
}

}  // namespace voxcone
