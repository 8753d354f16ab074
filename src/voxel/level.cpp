/// \file level.cpp
/// A field's level built from sorted runs of voxels (LevelBuilder): the topology and the
/// compact attributes, encoded as the runs come.

#include "level.h"

#include <algorithm>

namespace voxcone {
namespace voxel {

LevelBuilder::LevelBuilder(int level, double voxelSize, FieldQuantization* quant) : m_quant(quant) {
  m_out.level = level;
  m_out.voxelSize = voxelSize;
  m_out.invVoxelSize = float(1.0 / voxelSize);
  m_out.voxelSizeF = float(voxelSize);
  m_out.resolution = uint32_t(1) << level;
  m_out.tree = std::make_unique<IndexTree>(uint32_t(0));
  m_acc = std::make_unique<openvdb::tree::ValueAccessor<IndexTree>>(*m_out.tree);
}

LevelBuilder::~LevelBuilder() = default;

void LevelBuilder::append(const VoxelArrays& a) {
  Level& o = m_out;
  const bool lit = !a.radiance.empty();
  o.lit = o.lit || lit;
  for (size_t v = 0; v < a.size(); ++v) {
    const uint64_t key = a.keys[v];
    if ((key >> 6) != m_lastBrick) {
      flushBrick();
      if ((key >> 12) != m_lastSuper) {
        uint32_t si, sj, sk;
        voxel::unpackBrick(key >> 12, si, sj, sk);
        m_acc->setValue(openvdb::Coord(int32_t(si), int32_t(sj), int32_t(sk)), uint32_t(o.superMask.size()));
        o.superMask.push_back(0);
        o.superBase.push_back(uint32_t(o.brickMask.size()));
        m_lastSuper = key >> 12;
      }
      o.superMask.back() |= uint64_t(1) << ((key >> 6) & 63u);
      o.brickMask.push_back(0);
      o.brickBase.push_back(uint32_t(o.coverage.size()));
      m_lastBrick = key >> 6;
    }
    o.brickMask.back() |= uint64_t(1) << (key & 63u);
    o.coverage.push_back(Half(a.coverage[v]));
    o.normal.push_back(encodeNormal(a.normal[v]));
    if (!a.diffuse.empty()) m_diffuse.push_back(encodeUnorm8(a.diffuse[v]));
    if (lit) {
      m_radiance[0].push_back(encodeRgb9e5(a.radiance[v]));
      m_radiance[1].push_back(encodeRgb9e5(a.radianceBack[v]));
    }
    if (!a.axisFraction.empty())
      for (int c = 0; c < 3; ++c) o.axisFraction.push_back(encodeUnorm8(a.axisFraction[v][c]));
    if (m_quant) measure(a, v);
  }
}

Level LevelBuilder::finish() {
  flushBrick();
  Level& o = m_out;
  for (auto* v : {&o.superMask, &o.brickMask}) v->shrink_to_fit();
  for (auto* v : {&o.superBase, &o.brickBase}) v->shrink_to_fit();
  o.coverage.shrink_to_fit();
  o.normal.shrink_to_fit();
  o.axisFraction.shrink_to_fit();
  o.diffuse.shrink();
  for (SparseBricks<uint32_t>& side : o.radiance) side.shrink();
  if (o.level <= kDenseBrickLevel) {
    const size_t side = o.resolution >> 2;
    o.denseBricks.assign(std::max<size_t>(1, side * side * side), -1);
    for (auto it = o.tree->cbeginValueOn(); it; ++it) {
      const openvdb::Coord c = it.getCoord();
      o.forEachBrickOf(*it, uint32_t(c.x()), uint32_t(c.y()), uint32_t(c.z()),
                       [&](uint32_t b, uint32_t bi, uint32_t bj, uint32_t bk) {
                         o.denseBricks[(size_t(bk) * side + bj) * side + bi] = int32_t(b);
                       });
    }
  }
  m_acc.reset();
  return std::move(m_out);
}

void LevelBuilder::measure(const VoxelArrays& a, size_t v) {
  const Level& o = m_out;
  if (a.coverage[v] > 0.0f)
    m_quant->coverage.add(std::abs(double(float(o.coverage.back())) - double(a.coverage[v])) / double(a.coverage[v]));
  const float cosine = std::clamp(glm::dot(decodeNormal(o.normal.back()), a.normal[v]), -1.0f, 1.0f);
  m_quant->normal.add(double(std::acos(cosine)) * 180.0 / kPiD);
  if (!a.diffuse.empty()) m_quant->diffuse.add(std::abs(double(decodeUnorm8(m_diffuse.back())) - double(a.diffuse[v])));
  if (!a.radiance.empty()) {
    m_quant->addRadiance(a.radiance[v], m_radiance[0].back());
    m_quant->addRadiance(a.radianceBack[v], m_radiance[1].back());
  }
  if (!a.axisFraction.empty())
    for (int c = 0; c < 3; ++c)
      m_quant->axes.add(std::abs(double(decodeUnorm8(o.axisFraction[o.axisFraction.size() - 3 + size_t(c)])) -
                                 double(a.axisFraction[v][c])));
}

void LevelBuilder::flushBrick() {
  if (m_lastBrick == ~uint64_t(0)) return;
  auto keep = [&](auto& sparse, auto& pending, auto none) {
    const bool needed = std::any_of(pending.begin(), pending.end(), [&](auto c) { return c != none; });
    if (needed) {
      sparse.base.resize(m_out.brickMask.size() - 1, sparse.kNone);
      sparse.base.push_back(uint32_t(sparse.values.size()));
      sparse.values.insert(sparse.values.end(), pending.begin(), pending.end());
    }
    pending.clear();
  };
  keep(m_out.diffuse, m_diffuse, kAllDiffuse);
  for (int side = 0; side < 2; ++side) keep(m_out.radiance[side], m_radiance[side], uint32_t(0));
}

}  // namespace voxel
}  // namespace voxcone
