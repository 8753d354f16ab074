/// \file mitsuba_sensor.cpp
/// The Mitsuba 3 sensor (perspective: src/sensors/perspective.cpp), its film and sampler, and the
/// integrator element, as the scene's camera and render settings.

#include "mitsuba_loader_impl.h"

namespace voxcone {
namespace mitsuba_xml {

double MitsubaLoader::fovX(const Node& n, double fov, const std::string& axis, double aspect) const {
  const auto toX = [&](double f) { return 2.0 * std::atan(std::tan(0.5 * glm::radians(f)) * aspect); };
  if (axis == "x") return glm::radians(fov);
  if (axis == "y") return toX(fov);
  if (axis == "diagonal") {
    const double diagonal = 2.0 * std::tan(0.5 * glm::radians(fov));
    const double width = diagonal / std::sqrt(1.0 + 1.0 / (aspect * aspect));
    return 2.0 * std::atan(0.5 * width);
  }
  if (axis == "smaller") return aspect > 1.0 ? toX(fov) : glm::radians(fov);
  if (axis == "larger") return aspect < 1.0 ? toX(fov) : glm::radians(fov);
  fail(n, "fov_axis must be x, y, diagonal, smaller or larger, not '" + axis + "'");
}

void MitsubaLoader::parseSensor(const Node& n) {
  allowAttrs(n, {"type", "id", "name"});
  Props p(*this, n);
  if (p.type() != "perspective") fail(n, "unsupported sensor plugin '" + p.type() + "' (voxcone maps perspective)");
  RenderSettings& s = m_scene.render;
  // Film first: the field of view's axis depends on the aspect ratio. Mitsuba's hdrfilm
  // default is 768 x 576.
  s.width = 768;
  s.height = 576;
  for (const Node& f : p.takeObjects("film")) {
    allowAttrs(f, {"type", "id", "name"});
    Props fp(*this, f);
    if (fp.type() != "hdrfilm") fail(f, "unsupported film plugin '" + fp.type() + "' (voxcone maps hdrfilm)");
    s.width = fp.getInt("width", 768, 1, 32768);
    s.height = fp.getInt("height", 576, 1, 32768);
    // Output details voxcone decides itself (it writes float RGB EXR, PNG and a sidecar).
    fp.getString("file_format", "openexr");
    const std::string pf = fp.getString("pixel_format", "rgb");
    if (pf != "rgb" && pf != "rgba") fail(f, "pixel_format '" + pf + "': voxcone writes RGB");
    fp.getString("component_format", "float16");
    // voxcone's only pixel filter is the one-pixel box. Without an rfilter Mitsuba uses a
    // Gaussian (stddev 0.5 pixel): voxcone renders box then (docs/scenes.md says so); an explicit
    // other filter is an error.
    for (const Node& r : fp.takeObjects("rfilter")) {
      allowAttrs(r, {"type", "id", "name"});
      Props rp(*this, r);
      if (rp.type() != "box")
        fail(r, "unsupported rfilter '" + rp.type() + "': voxcone's pixel filter is the box of one pixel "
                "(use <rfilter type=\"box\"/>)");
      rp.finish();
    }
    fp.finish();
  }
  for (const Node& sm : p.takeObjects("sampler")) {
    allowAttrs(sm, {"type", "id", "name"});
    Props sp(*this, sm);
    const std::string& t = sp.type();
    // Mitsuba's samplers differ in their noise only: independent is voxcone's independent,
    // the stratified and low-discrepancy ones voxcone's Sobol (core/sampler.h).
    if (t == "independent") s.sampler = SamplerKind::Independent;
    else if (t == "ldsampler" || t == "stratified" || t == "multijitter" || t == "orthogonal") s.sampler = SamplerKind::Sobol;
    else fail(sm, "unsupported sampler plugin '" + t + "'");
    s.spp = sp.getInt("sample_count", 4, 1, 1 << 24);
    s.seed = uint64_t(sp.getInt("seed", 0, 0, INT32_MAX));
    sp.getBool("jitter", true);
    sp.finish();
  }
  const double aspect = double(s.width) / double(s.height);
  double fovYDeg = 0.0;
  if (p.has("fov") && p.has("focal_length")) fail(n, "give fov or focal_length, not both");
  std::string axis = p.getString("fov_axis", "x");
  std::transform(axis.begin(), axis.end(), axis.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  double fov;
  if (p.has("focal_length")) {
    // Mitsuba: a 35 mm film's diagonal (sqrt(36^2 + 24^2) mm) at this focal length.
    std::string f = p.getString("focal_length", "50mm");
    if (f.size() > 2 && f.substr(f.size() - 2) == "mm") f = f.substr(0, f.size() - 2);
    const double mm = number(n, f);
    if (!(mm > 0.0)) fail(n, "focal_length must be positive");
    fov = glm::degrees(2.0 * std::atan(std::sqrt(36.0 * 36.0 + 24.0 * 24.0) / (2.0 * mm)));
    axis = "diagonal";
  } else {
    fov = p.getFloat("fov", 0.0f, 1e-4f, 179.9f);
    if (!p.has("fov")) fail(n, "a perspective sensor needs fov (or focal_length)");
  }
  // The vertical angle as voxcone's camera takes it; given on the y axis it is kept exactly.
  if (axis == "y" || (axis == "smaller" && aspect > 1.0) || (axis == "larger" && aspect < 1.0))
    fovYDeg = fov;
  else
    fovYDeg = glm::degrees(2.0 * std::atan(std::tan(0.5 * fovX(n, fov, axis, aspect)) / aspect));
  if (!(fovYDeg >= 0.01 && fovYDeg <= 179.0))
    fail(n, "vertical field of view " + std::to_string(fovYDeg) + " degrees: voxcone's camera takes [0.01, 179]");
  // voxcone's rays start at the pinhole and have no far limit: near_clip and far_clip only
  // cut geometry nearer or farther than them in Mitsuba (docs/scenes.md says so).
  p.getFloat("near_clip", 0.01f, 0.0f);
  p.getFloat("far_clip", 1e4f, 0.0f);
  bool onlyLookat = false;
  const glm::dmat4 xf = p.getTransform("to_world", &onlyLookat);
  p.finish();

  // The camera frame. Mitsuba's perspective camera looks along local +z with local +y up
  // and maps local +x to the image's LEFT (its camera-to-sample transform scales x by -0.5,
  // src/sensors/perspective.cpp); look_at sets local x = cross(up, dir). So image right is
  // cross(dir, up), as in voxcone's Camera: the same lookat gives the same, unmirrored image.
  const DVec3 origin(xf[3]), x(xf[0]), y(xf[1]), z(xf[2]);
  const double lx = glm::length(x), ly = glm::length(y), lz = glm::length(z);
  if (!(lx > 0.0 && ly > 0.0 && lz > 0.0)) fail(n, "the sensor's to_world is singular");
  const double tol = 1e-5;
  if (std::abs(glm::dot(x, y)) > tol * lx * ly || std::abs(glm::dot(x, z)) > tol * lx * lz ||
      std::abs(glm::dot(y, z)) > tol * ly * lz || std::abs(lx - ly) > tol * lx || std::abs(lx - lz) > tol * lx)
    fail(n, "the sensor's to_world shears or scales unevenly: voxcone's pinhole camera cannot render that");
  if (glm::determinant(glm::dmat3(xf)) < 0.0)
    fail(n, "the sensor's to_world mirrors the image: voxcone's camera is not mirrored");
  if (!(largest(origin) <= detail::kMaxSceneReach))
    fail(n, "the camera lies beyond the range voxcone renders in float");
  Vec3 pos(origin), target, up;
  if (onlyLookat) {
    // Keep lookat's own target and up (the JSON camera's fields: round trips stay exact).
    target = m_lookTarget;
    up = m_lookUp;
  } else {
    target = Vec3(origin + z / lz);
    up = Vec3(y / ly);
  }
  m_scene.camera = Camera(pos, target, up, float(fovYDeg));
}

void MitsubaLoader::parseIntegrator(const Node& n) {
  allowAttrs(n, {"type", "id", "name"});
  Props p(*this, n);
  const std::string& t = p.type();
  RenderSettings& s = m_scene.render;
  // voxcone's own methods, a voxcone extension Mitsuba does not load (written by convert).
  if (t == "path" || t == "voxcone" || t == "pm" || t == "whitted") {
    s.method = t;
  } else {
    fail(n, "unsupported integrator plugin '" + t + "' (voxcone maps path; voxcone, pm and whitted are voxcone's)");
  }
  // Mitsuba's max_depth: the longest path in segments, 1 = emitters seen directly, 2 =
  // direct lighting, -1 = unbounded (Mitsuba 3 src/integrators/path.cpp: a vertex continues
  // while depth + 1 < max_depth). voxcone's maxDepth counts the same (path.cpp breaks when
  // depth + 1 >= maxDepth), so the number carries over; -1 becomes voxcone's largest, 1024.
  const int depth = p.getInt("max_depth", -1, -1, 1024);
  if (depth == 0) fail(n, "max_depth 0 renders nothing; voxcone needs at least 1");
  s.maxDepth = depth < 0 ? 1024 : depth;
  if (p.has("rr_depth"))
    fail(n, "rr_depth: voxcone's path integrator takes it as an option (voxcone render --options '{\"rr_depth\": N}')");
  if (p.getBool("hide_emitters", false)) fail(n, "hide_emitters: voxcone always shows emitters seen directly");
  if (t == "voxcone" || t == "pm") {
    s.photons = uint64_t(p.getInt("photons", 0, 0, INT32_MAX));
    s.causticPhotons = uint64_t(p.getInt("caustic_photons", 0, 0, INT32_MAX));
  }
  p.finish();
}

}  // namespace mitsuba_xml
}  // namespace voxcone
