// Embree 3 as an Accel (embree_accel.h). Compiled only where CMake finds Embree; accel.cpp offers
// "embree" then.

#include "voxcone/accel/embree_accel.h"

#include "voxcone/accel/embree_ray.h"
#include "voxcone/accel/triangle.h"
#include "voxcone/core/error.h"
#include "voxcone/core/timer.h"

#include <nlohmann/json.hpp>

#include <atomic>
#include <cstring>
#include <mutex>

namespace voxcone {

namespace {

/// Bytes Embree holds on a device (rtcSetDeviceMemoryMonitorFunction).
bool countBytes(void* user, ssize_t bytes, bool /*post*/) {
  static_cast<std::atomic<int64_t>*>(user)->fetch_add(int64_t(bytes));
  return true;
}

/// Embree reports errors through a callback (no exceptions across its C API): the first is
/// kept and thrown after the call.
void keepError(void* user, RTCError code, const char* str) {
  auto* first = static_cast<std::string*>(user);
  if (first->empty()) *first = "embree error " + std::to_string(int(code)) + ": " + (str ? str : "");
}

class EmbreeAccel final : public Accel {
public:
  EmbreeAccel(const std::vector<Vec3>& positions, const std::vector<UVec3>& triangles) {
    Timer timer;
    m_device = rtcNewDevice(nullptr);
    if (!m_device) throw Error("embree: rtcNewDevice failed");
    rtcSetDeviceErrorFunction(m_device, keepError, &m_error);
    rtcSetDeviceMemoryMonitorFunction(m_device, countBytes, &m_bytes);
    // The triangles every structure takes; Embree's primID indexes these, m_ids maps back.
    for (uint32_t i = 0; i < triangles.size(); ++i) {
      Bounds3 box;
      if (triangleBounds(positions, triangles[i], box)) m_ids.push_back(i);
    }
    m_scene = rtcNewScene(m_device);
    rtcSetSceneBuildQuality(m_scene, RTC_BUILD_QUALITY_MEDIUM);
    if (!m_ids.empty()) {
      RTCGeometry geom = rtcNewGeometry(m_device, RTC_GEOMETRY_TYPE_TRIANGLE);
      auto* vb = static_cast<float*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                             3 * sizeof(float), positions.size()));
      auto* ib = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                                3 * sizeof(uint32_t), m_ids.size()));
      if (!vb || !ib) throw Error("embree: cannot allocate the geometry buffers: " + m_error);
      for (size_t i = 0; i < positions.size(); ++i) std::memcpy(vb + 3 * i, &positions[i], 3 * sizeof(float));
      for (size_t i = 0; i < m_ids.size(); ++i) std::memcpy(ib + 3 * i, &triangles[m_ids[i]], 3 * sizeof(uint32_t));
      rtcCommitGeometry(geom);
      rtcAttachGeometry(m_scene, geom);
      rtcReleaseGeometry(geom);
    }
    rtcCommitScene(m_scene);
    if (!m_error.empty()) throw Error(m_error);
    RTCBounds b;
    rtcGetSceneBounds(m_scene, &b);
    if (!m_ids.empty()) {
      m_bounds.extend(Vec3(b.lower_x, b.lower_y, b.lower_z));
      m_bounds.extend(Vec3(b.upper_x, b.upper_y, b.upper_z));
    }
    m_seconds = timer.seconds();
  }
  ~EmbreeAccel() override {
    if (m_scene) rtcReleaseScene(m_scene);
    if (m_device) rtcReleaseDevice(m_device);
  }
  EmbreeAccel(const EmbreeAccel&) = delete;
  EmbreeAccel& operator=(const EmbreeAccel&) = delete;

  std::optional<Hit> intersect(const Ray& ray) const override {
    if (m_ids.empty()) return std::nullopt;
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    RTCRayHit rh;
    toEmbree(ray, ray.tMax, rh.ray);
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(m_scene, &ctx, &rh);
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return std::nullopt;
    // Embree's (u, v) weigh vertices 1 and 2, as Hit's (b1, b2).
    return Hit{rh.ray.tfar, m_ids[rh.hit.primID], rh.hit.u, rh.hit.v};
  }
  bool occluded(const Ray& ray, float tMax) const override {
    if (m_ids.empty()) return false;
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    RTCRay r;
    toEmbree(ray, tMax, r);
    rtcOccluded1(m_scene, &ctx, &r);
    return r.tfar < 0.0f;  // Embree marks an occluded ray with tfar = -inf
  }
  using Accel::occluded;
  Bounds3 bounds() const override { return m_bounds; }
  std::string kind() const override { return "embree"; }
  uint64_t bytes() const override { return uint64_t(std::max<int64_t>(0, m_bytes.load())); }
  double buildSeconds() const override { return m_seconds; }
  nlohmann::json statsJson() const override {
    return {{"kind", kind()}, {"bytes", bytes()}, {"build_seconds", m_seconds}, {"triangles", m_ids.size()},
            {"build_quality", "medium"}, {"version", RTC_VERSION_STRING}};
  }

private:
  RTCDevice m_device = nullptr;
  RTCScene m_scene = nullptr;
  std::string m_error;
  std::atomic<int64_t> m_bytes{0};
  std::vector<uint32_t> m_ids;  ///< Embree primID -> triangle index
  Bounds3 m_bounds;
  double m_seconds = 0.0;
};

}  // namespace

bool embreeAvailable() { return true; }

std::unique_ptr<Accel> buildEmbreeAccel(const std::vector<Vec3>& positions, const std::vector<UVec3>& triangles,
                                        Progress* progress) {
  if (progress) progress->start("embree", triangles.size());
  auto accel = std::make_unique<EmbreeAccel>(positions, triangles);
  if (progress) progress->finish();
  return accel;
}

}  // namespace voxcone
