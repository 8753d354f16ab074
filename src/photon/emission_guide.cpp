// Photon emission guided by a pilot's useful photons: a kd-tree over primary sample space.

#include "voxcone/photon/emission_guide.h"

#include "voxcone/core/error.h"

#include <algorithm>
#include <cmath>

namespace voxcone {

namespace {
/// No box is cut narrower than this in any dimension (2^-16: far below what a pilot's counts
/// can resolve), nor the tree deeper than kMaxDepth, so that equal samples end the recursion.
constexpr double kMinWidth = 0x1p-16;
constexpr int kMaxDepth = 48;

/// n log(n / v), 0 for n = 0: a box's part of the log-likelihood of its samples under the
/// piecewise-constant density (the constant total's term cancels in a cut's gain).
double likelihood(double n, double v) { return n > 0.0 ? n * std::log(n / v) : 0.0; }
}  // namespace

double EmissionSample::get(int d) const {
  switch (d) {
    case 0: return uLight;
    case 1: return double(uSide);
    case 2: return double(uPos.x);
    case 3: return double(uPos.y);
    case 4: return double(uDir.x);
    default: return double(uDir.y);
  }
}

void EmissionSample::set(int d, double v) {
  switch (d) {
    case 0: uLight = v; break;
    case 1: uSide = float(v); break;
    case 2: uPos.x = float(v); break;
    case 3: uPos.y = float(v); break;
    case 4: uDir.x = float(v); break;
    default: uDir.y = float(v); break;
  }
}

std::array<double, 12> EmissionGuide::unitBox() {
  std::array<double, 12> box{};
  for (int d = 0; d < EmissionSample::kDims; ++d) box[size_t(2 * d + 1)] = 1.0;
  return box;
}

EmissionGuide::EmissionGuide() {
  Leaf l;
  l.box = unitBox();
  m_leaves.push_back(l);
  m_nodes.push_back(Node{-1, 0.0, 0});
  m_cdf.push_back(1.0);
}

EmissionGuide EmissionGuide::fromUseful(std::vector<Useful> useful, const std::vector<double>& lightEdges,
                                        double floor, double splitCount, double maxRatio) {
  if (!(floor > 0.0) || floor > 1.0) throw Error("EmissionGuide: floor must lie in (0, 1]");
  if (!(splitCount >= 2.0)) throw Error("EmissionGuide: a box must hold at least 2 samples to be cut");
  if (!(maxRatio >= 1.0)) throw Error("EmissionGuide: the density ratio bound must be at least 1");
  for (size_t i = 0; i < lightEdges.size(); ++i)
    if (!(lightEdges[i] > 0.0 && lightEdges[i] < 1.0) || (i > 0 && !(lightEdges[i] > lightEdges[i - 1])))
      throw Error("EmissionGuide: light edges must increase inside (0, 1)");
  double total = 0.0;
  for (const Useful& u : useful) {
    for (int d = 0; d < EmissionSample::kDims; ++d)
      if (!(u.sample.get(d) >= 0.0 && u.sample.get(d) < 1.0))
        throw Error("EmissionGuide: useful samples must lie in [0, 1)");
    if (!(u.stores > 0.0) || !std::isfinite(u.stores)) throw Error("EmissionGuide: useful stores must be finite and > 0");
    total += u.stores;
  }
  EmissionGuide g;
  if (useful.empty() || floor == 1.0) return g;
  g.m_uniform = false;
  g.m_nodes.clear();
  g.m_leaves.clear();

  // Depth-first: node `self` holds samples [begin, end) in `box`.
  struct Task {
    uint32_t self;
    size_t begin, end;
    std::array<double, 12> box;
    int depth;
  };
  std::vector<Task> stack;
  g.m_nodes.push_back(Node{});
  stack.push_back({0, 0, useful.size(), unitBox(), 0});
  while (!stack.empty()) {
    const Task t = stack.back();
    stack.pop_back();
    const double n = double(t.end - t.begin);
    double stores = 0.0;
    for (size_t i = t.begin; i < t.end; ++i) stores += useful[i].stores;
    int best = -1;
    double bestCut = 0.0, bestGain = -1.0;
    if (n >= splitCount && t.depth < kMaxDepth) {
      for (int d = 0; d < EmissionSample::kDims; ++d) {
        const double lo = t.box[size_t(2 * d)], hi = t.box[size_t(2 * d + 1)];
        double cut = 0.5 * (lo + hi);
        if (d == 0) {
          // Only between lights: inside one light's interval uLight picks nothing but it. The
          // edge nearest the middle, if any lies inside.
          const auto it = std::lower_bound(lightEdges.begin(), lightEdges.end(), cut);
          double pick = -1.0;
          for (auto c : {it, it == lightEdges.begin() ? it : it - 1})
            if (c != lightEdges.end() && *c > lo && *c < hi && (pick < 0.0 || std::fabs(*c - cut) < std::fabs(pick - cut)))
              pick = *c;
          if (pick < 0.0) continue;
          cut = pick;
        } else if (hi - lo < 2.0 * kMinWidth) {
          continue;
        }
        double below = 0.0;
        for (size_t i = t.begin; i < t.end; ++i) below += useful[i].sample.get(d) < cut ? useful[i].stores : 0.0;
        const double f = (cut - lo) / (hi - lo);
        const double gain = likelihood(below, f) + likelihood(stores - below, 1.0 - f) - likelihood(stores, 1.0);
        if (gain > bestGain) {
          best = d;
          bestCut = cut;
          bestGain = gain;
        }
      }
    }
    if (best < 0) {
      Leaf l;
      l.box = t.box;
      for (int d = 0; d < EmissionSample::kDims; ++d) l.volume *= t.box[size_t(2 * d + 1)] - t.box[size_t(2 * d)];
      l.useful = stores;
      g.m_nodes[t.self] = Node{-1, 0.0, uint32_t(g.m_leaves.size())};
      g.m_leaves.push_back(l);
      continue;
    }
    const auto mid = std::partition(useful.begin() + std::ptrdiff_t(t.begin), useful.begin() + std::ptrdiff_t(t.end),
                                    [&](const Useful& u) { return u.sample.get(best) < bestCut; });
    const size_t m = size_t(mid - useful.begin());
    const uint32_t child = uint32_t(g.m_nodes.size());
    g.m_nodes[t.self] = Node{best, bestCut, child};
    g.m_nodes.push_back(Node{});
    g.m_nodes.push_back(Node{});
    Task below{child, t.begin, m, t.box, t.depth + 1}, above{child + 1, m, t.end, t.box, t.depth + 1};
    below.box[size_t(2 * best + 1)] = bestCut;
    above.box[size_t(2 * best)] = bestCut;
    stack.push_back(above);
    stack.push_back(below);
  }

  // The densities, (1 - floor) useful_b / (sum(useful) vol_b) + floor, raised to at least the
  // typical useful photon's (their mean over the useful stores) over maxRatio.
  const auto rho = [&](const Leaf& l) { return (1.0 - floor) * l.useful / (total * l.volume) + floor; };
  double typical = 0.0;
  for (const Leaf& l : g.m_leaves) typical += l.useful / total * rho(l);
  double c = 0.0;
  g.m_cdf.resize(g.m_leaves.size());
  for (size_t b = 0; b < g.m_leaves.size(); ++b) {
    Leaf& l = g.m_leaves[b];
    l.pmf = std::max(rho(l), typical / maxRatio) * l.volume;
    c += l.pmf;
    g.m_cdf[b] = c;
  }
  // The sum is 1 up to rounding; normalised so that the last entry is exactly 1.
  for (size_t b = 0; b < g.m_leaves.size(); ++b) {
    g.m_leaves[b].pmf /= c;
    g.m_cdf[b] /= c;
  }
  g.m_cdf.back() = 1.0;
  return g;
}

size_t EmissionGuide::leafOf(const EmissionSample& u) const {
  uint32_t node = 0;
  while (m_nodes[node].dim >= 0) node = m_nodes[node].child + (u.get(m_nodes[node].dim) < m_nodes[node].cut ? 0 : 1);
  return m_nodes[node].child;
}

double EmissionGuide::remap(EmissionSample& u) const {
  if (m_uniform) return 1.0;
  // The leaf by the guided CDF, and what is left of uLight, rescaled to [0,1), for the leaf's
  // own uLight coordinate; the other coordinates, uniform, placed in its box.
  const size_t b = std::min(size_t(std::upper_bound(m_cdf.begin(), m_cdf.end(), u.uLight) - m_cdf.begin()),
                            m_leaves.size() - 1);
  const Leaf& l = m_leaves[b];
  const double lo = b > 0 ? m_cdf[b - 1] : 0.0;
  const double r = std::clamp((u.uLight - lo) / l.pmf, 0.0, std::nextafter(1.0, 0.0));
  for (int d = 0; d < EmissionSample::kDims; ++d) {
    const double a = l.box[size_t(2 * d)], z = l.box[size_t(2 * d + 1)];
    const double v = a + (d == 0 ? r : u.get(d)) * (z - a);
    // Rounding may reach the box's top; the coordinate stays below it (and below 1).
    const double top = d == 0 ? std::nextafter(z, 0.0) : double(std::nextafter(float(z), 0.0f));
    u.set(d, std::clamp(v, a, std::max(a, top)));
  }
  return l.volume / l.pmf;
}

void EmissionGuide::expectedYield(double emitted, double& usefulPerPhoton, double& effectivePerPhoton,
                                  const std::vector<double>& useful) const {
  usefulPerPhoton = effectivePerPhoton = 0.0;
  if ((!useful.empty() && useful.size() != leaves()) || !(emitted > 0.0)) return;
  // Leaf b's rate (useful per photon emitted in it) is r_b = useful_b / (emitted vol_b). Per
  // guided photon: useful sum_b p_b r_b; weights w_b = vol_b / p_b, sum w = sum_b useful_b /
  // emitted as unguided, sum w^2 = sum_b p_b r_b w_b^2 = sum_b useful_b vol_b / (emitted p_b).
  double total = 0.0, sumW2 = 0.0;
  for (size_t b = 0; b < leaves(); ++b) {
    const double u = useful.empty() ? m_leaves[b].useful : useful[b];
    if (!(u > 0.0)) continue;
    const Leaf& l = m_leaves[b];
    total += u;
    usefulPerPhoton += l.pmf * u / (emitted * l.volume);
    sumW2 += u * l.volume / (emitted * l.pmf);
  }
  const double sumW = total / emitted;
  effectivePerPhoton = sumW2 > 0.0 ? sumW * sumW / sumW2 : 0.0;
}

void EmissionGuide::heldOutYield(const std::vector<Useful>& useful, const std::vector<double>& lightEdges, double floor,
                                 double splitCount, double maxRatio, double emitted, double& usefulPerPhoton,
                                 double& effectivePerPhoton) {
  usefulPerPhoton = effectivePerPhoton = 0.0;
  std::vector<Useful> halves[2];
  for (size_t i = 0; i < useful.size(); ++i) halves[i % 2].push_back(useful[i]);
  for (int k = 0; k < 2; ++k) {
    const EmissionGuide g = fromUseful(halves[k], lightEdges, floor, splitCount, maxRatio);
    std::vector<double> judged(g.leaves(), 0.0);
    for (const Useful& u : halves[1 - k]) judged[g.leafOf(u.sample)] += u.stores;
    // Each half is a sample of the useful photons of half the pilot's emission.
    double per = 0.0, effective = 0.0;
    g.expectedYield(0.5 * emitted, per, effective, judged);
    usefulPerPhoton += 0.5 * per;
    effectivePerPhoton += 0.5 * effective;
  }
}

}  // namespace voxcone
