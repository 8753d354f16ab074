#include "voxcone/scene/light_tree.h"

#include <algorithm>
#include <array>
#include <cmath>

namespace voxcone {

namespace {

/// cos(max(0, a - b)) from the sines and cosines of angles a, b in [0, pi].
inline float cosSubClamped(float sinA, float cosA, float sinB, float cosB) {
  return cosA > cosB ? 1.0f : cosA * cosB + sinA * sinB;
}
/// sin(max(0, a - b)) likewise.
inline float sinSubClamped(float sinA, float cosA, float sinB, float cosB) {
  return cosA > cosB ? 0.0f : sinA * cosB - cosA * sinB;
}
inline float safeAcos(float x) { return std::acos(std::clamp(x, -1.0f, 1.0f)); }

/// The solid-angle measure of the orientation bounds (pbrt-v4's M_omega): the cone of normals
/// widened by the emission's reach.
float orientationMeasure(const LightBounds& b) {
  const float theta_o = safeAcos(b.cosTheta_o), theta_e = safeAcos(b.cosTheta_e);
  const float theta_w = std::min(theta_o + theta_e, kPi);
  const float sinTheta_o = safeSqrt(1.0f - b.cosTheta_o * b.cosTheta_o);
  return 2.0f * kPi * (1.0f - b.cosTheta_o) +
         0.5f * kPi * (2.0f * theta_w * sinTheta_o - std::cos(theta_o - 2.0f * theta_w) - 2.0f * theta_o * sinTheta_o +
                       b.cosTheta_o);
}

}  // namespace

ImportanceBounds ImportanceBounds::of(const LightBounds& b) {
  ImportanceBounds ib;
  ib.centre = b.bounds.center();
  ib.r2 = 0.25f * glm::dot(b.bounds.diagonal(), b.bounds.diagonal());
  ib.r = std::sqrt(ib.r2);
  ib.w = b.w;
  ib.phi = b.phi;
  ib.cosTheta_o = b.cosTheta_o;
  ib.sinTheta_o = safeSqrt(1.0f - b.cosTheta_o * b.cosTheta_o);
  ib.cosTheta_e = b.cosTheta_e;
  ib.twoSided = b.twoSided;
  return ib;
}

float LightBounds::importance(const Vec3& p, const Vec3* n) const { return ImportanceBounds::of(*this).importance(p, n); }

float ImportanceBounds::importance(const Vec3& p, const Vec3* n) const {
  if (!(phi > 0.0f)) return 0.0f;
  const Vec3 d = p - centre;
  const float dist2 = glm::dot(d, d);
  // The distance is at least the box's bounding radius: inside or near the box every light of
  // it may be as close as that.
  const float d2 = std::max({dist2, r2, 1e-20f});
  const float invDist = dist2 > 0.0f ? 1.0f / std::sqrt(dist2) : 0.0f;
  const Vec3 wi = dist2 > 0.0f ? d * invDist : Vec3(0.0f, 0.0f, 1.0f);
  // The cone of directions from p that the box's bounding sphere subtends (every direction from
  // inside it): sin theta_b = r / dist.
  const bool inside = dist2 <= r2;
  const float sinTheta_b = inside ? 0.0f : r * invDist;
  const float cosTheta_b = inside ? -1.0f : safeSqrt(1.0f - sinTheta_b * sinTheta_b);
  // The smallest angle between an emission normal and a direction from the bounds to p:
  // theta_w - theta_o - theta_b, clamped at 0 (a point light's cone holds every direction).
  float cosThetap = 1.0f;
  if (cosTheta_o > -1.0f) {
    float cosTheta_w = glm::dot(w, wi);
    if (twoSided) cosTheta_w = std::fabs(cosTheta_w);
    const float sinTheta_w = safeSqrt(1.0f - cosTheta_w * cosTheta_w);
    const float cosTheta_x = cosSubClamped(sinTheta_w, cosTheta_w, sinTheta_o, cosTheta_o);
    const float sinTheta_x = sinSubClamped(sinTheta_w, cosTheta_w, sinTheta_o, cosTheta_o);
    cosThetap = cosSubClamped(sinTheta_x, cosTheta_x, sinTheta_b, cosTheta_b);
    if (cosThetap <= cosTheta_e) return 0.0f;
  }
  float imp = phi * cosThetap / d2;
  if (n) {
    // The receiver's |cos| at most that of the direction to the box's centre widened by the
    // box's angle.
    const float cosTheta_i = std::fabs(glm::dot(wi, *n));
    const float sinTheta_i = safeSqrt(1.0f - cosTheta_i * cosTheta_i);
    imp *= cosSubClamped(sinTheta_i, cosTheta_i, sinTheta_b, cosTheta_b);
  }
  return std::max(imp, 0.0f);
}

LightBounds unite(const LightBounds& a, const LightBounds& b) {
  if (!(a.phi > 0.0f)) return b;
  if (!(b.phi > 0.0f)) return a;
  LightBounds r;
  r.bounds = unite(a.bounds, b.bounds);
  r.phi = a.phi + b.phi;
  r.cosTheta_e = std::min(a.cosTheta_e, b.cosTheta_e);
  r.twoSided = a.twoSided || b.twoSided;
  // The smallest cone holding both cones of normals (pbrt-v4's DirectionCone Union).
  const float theta_a = safeAcos(a.cosTheta_o), theta_b = safeAcos(b.cosTheta_o);
  const float theta_d = safeAcos(glm::dot(a.w, b.w));
  if (std::min(theta_d + theta_b, kPi) <= theta_a) {
    r.w = a.w;
    r.cosTheta_o = a.cosTheta_o;
  } else if (std::min(theta_d + theta_a, kPi) <= theta_b) {
    r.w = b.w;
    r.cosTheta_o = b.cosTheta_o;
  } else {
    const float theta_o = 0.5f * (theta_a + theta_d + theta_b);
    const Vec3 axis = glm::cross(a.w, b.w);
    const float len = glm::length(axis);
    if (theta_o >= kPi || !(len > 1e-12f)) {
      r.w = a.w;
      r.cosTheta_o = -1.0f;
    } else {
      // a.w turned towards b.w by theta_o - theta_a about their common perpendicular.
      const float theta_r = theta_o - theta_a;
      const Vec3 k = axis / len;
      r.w = glm::normalize(a.w * std::cos(theta_r) + glm::cross(k, a.w) * std::sin(theta_r));
      r.cosTheta_o = std::cos(theta_o);
    }
  }
  return r;
}

LightTree::LightTree(const std::vector<LightBounds>& lights) {
  m_leafOf.assign(lights.size(), UINT32_MAX);
  std::vector<uint32_t> idx;
  for (uint32_t i = 0; i < lights.size(); ++i)
    if (lights[i].phi > 0.0f) idx.push_back(i);
  if (idx.empty()) return;
  m_nodes.reserve(2 * idx.size() - 1);
  build(idx, 0, idx.size(), lights, UINT32_MAX);
}

uint32_t LightTree::build(std::vector<uint32_t>& idx, size_t begin, size_t end, const std::vector<LightBounds>& lights,
                          uint32_t parent) {
  const uint32_t self = static_cast<uint32_t>(m_nodes.size());
  m_nodes.emplace_back();
  m_nodes[self].parent = parent;
  m_nodes[self].depth = parent == UINT32_MAX ? 0 : uint8_t(std::min(255, m_nodes[parent].depth + 1));
  if (end - begin == 1) {
    Node& leaf = m_nodes[self];
    leaf.lb = lights[idx[begin]];
    leaf.ib = ImportanceBounds::of(leaf.lb);
    leaf.light = idx[begin];
    leaf.leaf = true;
    m_leafOf[idx[begin]] = self;
    return self;
  }
  // The split of least surface-area-orientation cost over 12 bins of the centroids per axis.
  Bounds3 bounds, centroids;
  for (size_t i = begin; i < end; ++i) {
    bounds.extend(lights[idx[i]].bounds);
    centroids.extend(lights[idx[i]].bounds.center());
  }
  constexpr int kBins = 12;
  float bestCost = kInf;
  int bestDim = -1, bestBin = -1;
  const Vec3 cd = centroids.diagonal();
  const float maxExtent = std::max({bounds.diagonal().x, bounds.diagonal().y, bounds.diagonal().z});
  const auto binOf = [&](int dim, uint32_t li) {
    const float t = (lights[li].bounds.center()[dim] - centroids.lo[dim]) / cd[dim];
    return std::clamp(static_cast<int>(t * kBins), 0, kBins - 1);
  };
  const auto cost = [](const LightBounds& b) { return b.phi > 0.0f ? b.phi * orientationMeasure(b) * b.bounds.area() : 0.0f; };
  for (int dim = 0; dim < 3; ++dim) {
    if (!(cd[dim] > 0.0f)) continue;
    std::array<LightBounds, kBins> bin{};
    for (size_t i = begin; i < end; ++i) {
      LightBounds& b = bin[size_t(binOf(dim, idx[i]))];
      b = unite(b, lights[idx[i]]);
    }
    // above[s]: bins s + 1 and up together, for the sweep of splits after bin s.
    std::array<LightBounds, kBins> above{};
    for (int s = kBins - 2; s >= 0; --s) above[size_t(s)] = unite(above[size_t(s) + 1], bin[size_t(s) + 1]);
    const float kr = maxExtent / std::max(bounds.diagonal()[dim], 1e-30f);
    LightBounds below;
    for (int split = 0; split < kBins - 1; ++split) {
      below = unite(below, bin[size_t(split)]);
      if (!(below.phi > 0.0f) || !(above[size_t(split)].phi > 0.0f)) continue;
      const float c = kr * (cost(below) + cost(above[size_t(split)]));
      if (c < bestCost) {
        bestCost = c;
        bestDim = dim;
        bestBin = split;
      }
    }
  }
  size_t mid;
  if (bestDim >= 0) {
    const auto it = std::partition(idx.begin() + long(begin), idx.begin() + long(end),
                                   [&](uint32_t li) { return binOf(bestDim, li) <= bestBin; });
    mid = size_t(it - idx.begin());
  } else {
    mid = begin;
  }
  if (mid == begin || mid == end) {
    // Coincident centroids (or zero-cost bins): halves by index, which terminates.
    mid = (begin + end) / 2;
  }
  build(idx, begin, mid, lights, self);
  const uint32_t second = build(idx, mid, end, lights, self);
  Node& node = m_nodes[self];
  node.second = second;
  node.lb = unite(m_nodes[self + 1].lb, m_nodes[second].lb);
  node.ib = ImportanceBounds::of(node.lb);
  return self;
}

uint32_t LightTree::descend(uint32_t i, const Vec3& p, const Vec3* n, float& u, float& pmf) const {
  const uint32_t c0 = i + 1, c1 = m_nodes[i].second;
  const float p0 = firstChildProbability(i, p, n);
  if (!(p0 >= 0.0f)) return UINT32_MAX;
  if (u < p0) {
    u = std::min(u / p0, kOneMinusEpsilon);
    pmf *= p0;
    return c0;
  }
  u = std::min((u - p0) / (1.0f - p0), kOneMinusEpsilon);
  pmf *= 1.0f - p0;
  return c1;
}

float LightTree::firstChildProbability(uint32_t i, const Vec3& p, const Vec3* n) const {
  const float i0 = m_nodes[i + 1].ib.importance(p, n), i1 = m_nodes[m_nodes[i].second].ib.importance(p, n);
  const float sum = i0 + i1;
  return sum > 0.0f ? i0 / sum : -1.0f;
}

bool LightTree::sample(const Vec3& p, const Vec3* n, float& u, uint32_t& light, float& pmf) const {
  if (m_nodes.empty()) return false;
  uint32_t i = 0;
  pmf = 1.0f;
  while (!m_nodes[i].leaf) {
    i = descend(i, p, n, u, pmf);
    if (i == UINT32_MAX) return false;
  }
  light = m_nodes[i].light;
  return pmf > 0.0f;
}

float LightTree::pmf(const Vec3& p, const Vec3* n, uint32_t light) const { return pmfUp(p, n, light, false, 0.0f); }

float LightTree::pmfUp(const Vec3& p, const Vec3* n, uint32_t light, bool split, float sinSplit2) const {
  if (light >= m_leafOf.size() || m_leafOf[light] == UINT32_MAX) return 0.0f;
  float pmf = 1.0f;
  uint32_t i = m_leafOf[light];
  while (m_nodes[i].parent != UINT32_MAX) {
    const uint32_t parent = m_nodes[i].parent;
    if (!(split && splits(m_nodes[parent], p, sinSplit2))) {
      // The same arithmetic as descend's choice.
      const float p0 = firstChildProbability(parent, p, n);
      if (!(p0 >= 0.0f)) return 0.0f;
      pmf *= i == parent + 1 ? p0 : 1.0f - p0;
    }
    i = parent;
  }
  return pmf;
}

bool LightTree::splits(const Node& node, const Vec3& p, float sinSplit2) const {
  if (node.leaf || node.depth >= kSplitDepth) return false;
  const Vec3 d = p - node.ib.centre;
  const float dist2 = glm::dot(d, d);
  // Inside the sphere, or its angular radius asin(r / dist) above the split angle.
  return dist2 <= node.ib.r2 || node.ib.r2 > sinSplit2 * dist2;
}

namespace {
float sinSquared(float splitAngle) { return splitAngle >= 0.5f * kPi ? 1.0f : sqr(std::sin(splitAngle)); }
}  // namespace

int LightTree::sampleSplit(const Vec3& p, const Vec3* n, float u, float splitAngle, Choice* out) const {
  if (m_nodes.empty()) return 0;
  const float sinSplit2 = sinSquared(splitAngle);
  // Depth-first over the groups: a stack of (node, u, pmf so far in its group).
  struct Item {
    uint32_t node;
    float u, pmf;
  };
  Item stack[kMaxChoices + 1];
  int top = 0, count = 0;
  stack[top++] = {0, u, 1.0f};
  while (top > 0) {
    Item it = stack[--top];
    while (it.node != UINT32_MAX) {
      const Node& node = m_nodes[it.node];
      if (node.leaf) {
        if (it.pmf > 0.0f) out[count++] = {node.light, it.pmf, it.u};
        break;
      }
      if (splits(node, p, sinSplit2)) {
        // Both children, each with the same number (their choices are independent groups).
        stack[top++] = {node.second, it.u, it.pmf};
        it.node = it.node + 1;
      } else {
        it.node = descend(it.node, p, n, it.u, it.pmf);
      }
    }
  }
  return count;
}

float LightTree::pmfSplit(const Vec3& p, const Vec3* n, uint32_t light, float splitAngle) const {
  return pmfUp(p, n, light, true, sinSquared(splitAngle));
}

}  // namespace voxcone
