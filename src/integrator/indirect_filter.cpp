#include "voxcone/integrator/indirect_filter.h"

#include <tbb/parallel_for.h>

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
}  // namespace

bool sameFilterSurface(const IndirectBuffer& in, size_t p, size_t q) {
  return in.filterable[p] && in.filterable[q] && in.material[q] == in.material[p] &&
         glm::dot(in.normal[p], in.normal[q]) >= kMinNormalCos &&
         std::fabs(glm::dot(in.normal[p], in.position[q] - in.position[p])) <= kPlaneFootprints * in.footprint[p];
}

std::vector<Vec3> filterIndirect(const IndirectBuffer& in, int radius) {
  const int w = in.width, h = in.height;
  std::vector<Vec3> out = in.indirect;
  if (radius <= 0) return out;
  // The window's edge at 2 sigma: the Gaussian has fallen to e^-2 there, so cutting it off
  // loses little weight.
  const float sigma = 0.5f * float(radius);
  const float inv2s2 = 1.0f / (2.0f * sigma * sigma);
  const int side = 2 * radius + 1;
  const auto linked = [&](size_t a, int bit) { return in.link.empty() || ((in.link[a] >> bit) & 1u); };
  tbb::parallel_for(0, h, [&](int y) {
    // The window's pixels reached from the centre through links (breadth first), per row.
    std::vector<uint8_t> reached(size_t(side) * side);
    std::vector<int> queue(size_t(side) * side);
    for (int x = 0; x < w; ++x) {
      const size_t p = size_t(y) * size_t(w) + size_t(x);
      if (!in.filterable[p]) continue;
      std::fill(reached.begin(), reached.end(), uint8_t(0));
      size_t head = 0, tail = 0;
      const auto cell = [&](int qx, int qy) { return size_t(qy - y + radius) * side + size_t(qx - x + radius); };
      reached[cell(x, y)] = 1;
      queue[tail++] = int(cell(x, y));
      // Summed in double in a fixed order (the queue's): the result does not depend on threads.
      DVec3 sum(0.0);
      double wsum = 0.0;
      while (head < tail) {
        const int c = queue[head++];
        const int qx = x - radius + c % side, qy = y - radius + c / side;
        const size_t q = size_t(qy) * size_t(w) + size_t(qx);
        // Its weight (Gaussian in the image times cos^8 of the normals: a soft edge inside the
        // 25-degree cut; measured, dropping it leaves both canonical scenes' error unchanged),
        // then its linked neighbours on the centre's surface.
        const float cosN = glm::dot(in.normal[p], in.normal[q]);
        const float d2 = float(sqr(qx - x) + sqr(qy - y));
        const float c2 = cosN * cosN, c4 = c2 * c2;
        const double wq = double(std::exp(-d2 * inv2s2) * c4 * c4);
        sum += wq * DVec3(in.indirect[q]);
        wsum += wq;
        const int nx[4] = {qx + 1, qx - 1, qx, qx}, ny[4] = {qy, qy, qy + 1, qy - 1};
        for (int k = 0; k < 4; ++k) {
          if (nx[k] < 0 || ny[k] < 0 || nx[k] >= w || ny[k] >= h) continue;
          if (std::abs(nx[k] - x) > radius || std::abs(ny[k] - y) > radius) continue;
          const size_t cq = cell(nx[k], ny[k]);
          if (reached[cq]) continue;
          const size_t n = size_t(ny[k]) * size_t(w) + size_t(nx[k]);
          // The link between q and n is stored on the left or upper one of the two: q for the
          // right and lower neighbours (k = 0, 2), n for the left and upper ones; bit k / 2.
          if (!linked(k % 2 == 0 ? q : n, k / 2) || !sameFilterSurface(in, p, n)) continue;
          reached[cq] = 1;
          queue[tail++] = int(cq);
        }
      }
      if (wsum > 0.0) out[p] = Vec3(sum / wsum);
    }
  });
  return out;
}

}  // namespace voxcone
