#include "voxcone/integrator/indirect_filter.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <limits>

namespace voxcone {

namespace {
/// Neighbours' normals within acos(0.9) = 25.8 degrees of the pixel's: curved surfaces keep
/// their neighbours (the dragon's flat-shaded facets), creases and corners do not.
/// Measured (256x256 defaults): 0.8 and 0.97 give the same error on cornell-box (38.27 dB) and
/// cornell-dragon (39.00 dB): the walls meet at 90 degrees, and the dragon's filterable pixels
/// are already limited by renderImage's within-pixel test.
constexpr float kMinNormalCos = 0.9f;
/// Neighbours within this many of the pixel's footprints of its tangent plane: the same
/// surface, not one behind it or in front. 1 and 4 measured as 2 (38.27 / 39.00 dB); the step
/// test (indirect_filter tests) needs it below 3.
constexpr float kPlaneFootprints = 2.0f;
/// surfaceReach looks past at most this many pixels in a row that see more than one surface
/// (an edge's) for the surface beyond them. An edge crossing a row or column of box-filtered
/// pixels lies inside one of them; a walk along a diagonal can meet two (the edge passes
/// between the pixel's corner and its neighbour's). A third in a row is a gap, not an edge:
/// what lies beyond it need not meet the pixel's surface (the test's three-pixel case).
constexpr int kEdgePixels = 2;

/// Whether a point (position, unit normal) lies on pixel p's plane: normals within 25 degrees,
/// within kPlaneFootprints of p's footprints of its tangent plane.
bool onPlane(const IndirectBuffer& in, size_t p, const Vec3& position, const Vec3& normal) {
  return glm::dot(in.normal[p], normal) >= kMinNormalCos &&
         std::fabs(glm::dot(in.normal[p], position - in.position[p])) <= kPlaneFootprints * in.footprint[p];
}

/// The normals' cosine when a point (position, unit normal, material) lies on filterable pixel
/// p's surface by the filter's tests, else -2.
float cosOnSurface(const IndirectBuffer& in, size_t p, const Vec3& position, const Vec3& normal, uint32_t material) {
  if (!in.filterable[p] || material != in.material[p] || !onPlane(in, p, position, normal)) return -2.0f;
  return glm::dot(in.normal[p], normal);
}
}  // namespace

bool onFilterSurface(const IndirectBuffer& in, size_t p, const Vec3& position, const Vec3& normal, uint32_t material) {
  return cosOnSurface(in, p, position, normal, material) >= kMinNormalCos;
}

bool sameFilterSurface(const IndirectBuffer& in, size_t p, size_t q) {
  return in.filterable[q] && onFilterSurface(in, p, in.position[q], in.normal[q], in.material[q]);
}

namespace {
bool isEstimated(const IndirectBuffer& in, size_t p) { return in.estimated.empty() || in.estimated[p]; }

/// Visits what filterable pixel p = (x, y) reaches along its row (bit 0) or column (bit 1):
/// visit(q, d, cosN) for q at distance d = 1 .. radius on each side (cosN: the normals'
/// cosine), walking outwards and stopping at the first neighbour that is not linked to the
/// previous one (the link between two neighbours is stored on the left or upper one) or not on
/// p's surface (sameFilterSurface). visit returns false to end the whole walk.
template <class Visit>
void walk(const IndirectBuffer& in, int radius, int bit, size_t p, int x, int y, Visit&& visit) {
  const size_t stride = bit == 0 ? 1 : size_t(in.width);
  const int pos = bit == 0 ? x : y, len = bit == 0 ? in.width : in.height;
  for (int dir = -1; dir <= 1; dir += 2) {
    size_t prev = p;
    for (int d = 1; d <= radius; ++d) {
      const int at = pos + dir * d;
      if (at < 0 || at >= len) break;
      const size_t q = dir > 0 ? prev + stride : prev - stride;
      const size_t holder = dir > 0 ? prev : q;
      if (!(in.link.empty() || ((in.link[holder] >> bit) & 1u)) || !in.filterable[q]) break;
      // sameFilterSurface(in, p, q), keeping the normals' cosine for the weight.
      const float cosN = cosOnSurface(in, p, in.position[q], in.normal[q], in.material[q]);
      if (!(cosN >= kMinNormalCos)) break;
      if (!in.reach.empty() &&
          !(glm::length(in.position[q] - in.position[p]) <= std::min(in.reach[p], in.reach[q])))
        break;
      if (!visit(q, d, cosN)) return;
      prev = q;
    }
  }
}

/// One pass over the image (rows in parallel): f(p, x, y) for every filterable pixel.
template <class F>
void forEachFilterable(const IndirectBuffer& in, F&& f) {
  tbb::parallel_for(0, in.height, [&](int y) {
    for (int x = 0; x < in.width; ++x) {
      const size_t p = size_t(y) * size_t(in.width) + size_t(x);
      if (in.filterable[p]) f(p, x, y);
    }
  });
}

/// The filter's weighted sums: num / den is a pixel's filtered light (den 0: no estimated pixel
/// reached). Separable, rows then columns (as a separable bilateral filter): the row pass sums
/// each pixel's estimated neighbours along its row, the column pass sums the row pass's sums
/// along the column, each over walk()'s reach, so light reaches a pixel only along an L-shaped
/// chain of links. Weights: a Gaussian of standard deviation radius / 2 per axis (their product
/// is the 2D Gaussian), times cos^8 of the normals (a soft edge inside the 25-degree cut;
/// measured, dropping it leaves both canonical scenes' error unchanged). Fixed order: no thread
/// dependence.
void filterSums(const IndirectBuffer& in, int radius, std::vector<DVec3>& num, std::vector<double>& den) {
  const size_t n = size_t(in.width) * size_t(in.height);
  // The window's edge at 2 sigma: the Gaussian has fallen to e^-2 there.
  const float sigma = 0.5f * float(radius);
  std::vector<float> gauss(size_t(radius) + 1);
  for (int d = 0; d <= radius; ++d) gauss[size_t(d)] = std::exp(-float(d * d) / (2.0f * sigma * sigma));
  const auto cos8 = [](float c) {
    const float c2 = c * c, c4 = c2 * c2;
    return c4 * c4;
  };
  const auto pass = [&](const std::vector<DVec3>& srcNum, const std::vector<double>& srcDen, int bit,
                        std::vector<DVec3>& dstNum, std::vector<double>& dstDen) {
    dstNum.assign(n, DVec3(0.0));
    dstDen.assign(n, 0.0);
    forEachFilterable(in, [&](size_t p, int x, int y) {
      DVec3 sn = srcNum[p];
      double sd = srcDen[p];
      walk(in, radius, bit, p, x, y, [&](size_t q, int d, float cosN) {
        if (srcDen[q] == 0.0) return true;  // most of the row pass's sources: no estimate
        const double wq = double(gauss[size_t(d)] * cos8(cosN));
        sn += wq * srcNum[q];
        sd += wq * srcDen[q];
        return true;
      });
      dstNum[p] = sn;
      dstDen[p] = sd;
    });
  };
  std::vector<DVec3> num0(n, DVec3(0.0));
  std::vector<double> den0(n, 0.0);
  for (size_t p = 0; p < n; ++p)
    if (in.filterable[p] && isEstimated(in, p)) {
      num0[p] = DVec3(in.indirect[p]);
      den0[p] = 1.0;
    }
  std::vector<DVec3> rowNum;
  std::vector<double> rowDen;
  pass(num0, den0, 0, rowNum, rowDen);
  pass(rowNum, rowDen, 1, num, den);
}
}  // namespace

std::vector<Vec3> filterIndirect(const IndirectBuffer& in, int radius) {
  std::vector<Vec3> out = in.indirect;
  if (radius <= 0) return out;
  std::vector<DVec3> num;
  std::vector<double> den;
  filterSums(in, radius, num, den);
  for (size_t p = 0; p < out.size(); ++p)
    if (in.filterable[p] && den[p] > 0.0) out[p] = Vec3(num[p] / den[p]);
  return out;
}

std::vector<float> surfaceReach(const IndirectBuffer& in, int radius, float scale) {
  const size_t n = size_t(in.width) * size_t(in.height);
  std::vector<float> out(n, std::numeric_limits<float>::infinity());
  static constexpr int kDx[8] = {1, -1, 0, 0, 1, 1, -1, -1}, kDy[8] = {0, 0, 1, -1, 1, -1, 1, -1};
  forEachFilterable(in, [&](size_t p, int x, int y) {
    float nearest = std::numeric_limits<float>::infinity();
    for (int k = 0; k < 8; ++k) {
      int between = 0;  // pixels passed in a row that see more than one surface
      for (int step = 1; step <= radius; ++step) {
        const int qx = x + kDx[k] * step, qy = y + kDy[k] * step;
        if (qx < 0 || qy < 0 || qx >= in.width || qy >= in.height) break;
        const size_t q = size_t(qy) * size_t(in.width) + size_t(qx);
        if (!in.filterable[q]) {
          // Nothing there (the sky, a mirror) beyond the pixels an edge mixes.
          if (++between > kEdgePixels) break;
          continue;
        }
        between = 0;
        // The same surface whatever its material: on.
        if (onPlane(in, p, in.position[q], in.normal[q])) continue;
        nearest = std::min(nearest, glm::length(in.position[q] - in.position[p]));
        break;
      }
    }
    out[p] = scale * nearest;
  });
  return out;
}

std::vector<uint8_t> unfilledPixels(const IndirectBuffer& in, int radius) {
  // filterSums' reach without its sums (its weights are positive, so den > 0 exactly where an
  // estimated pixel is reached): each walk ends at the first pixel that carries one.
  const size_t n = size_t(in.width) * size_t(in.height);
  std::vector<uint8_t> row(n, 0u), reached(n, 0u);
  for (size_t p = 0; p < n; ++p) row[p] = in.filterable[p] && isEstimated(in, p);
  const auto pass = [&](const std::vector<uint8_t>& src, int bit, std::vector<uint8_t>& dst) {
    forEachFilterable(in, [&](size_t p, int x, int y) {
      bool found = src[p] != 0u;
      if (!found && radius > 0)
        walk(in, radius, bit, p, x, y, [&](size_t q, int, float) {
          found = src[q] != 0u;
          return !found;
        });
      dst[p] = found ? 1u : 0u;
    });
  };
  std::vector<uint8_t> column(n, 0u);
  pass(row, 0, reached);
  pass(reached, 1, column);
  std::vector<uint8_t> out(n, 0u);
  for (size_t p = 0; p < n; ++p) out[p] = in.filterable[p] && !column[p];
  return out;
}

}  // namespace voxcone
