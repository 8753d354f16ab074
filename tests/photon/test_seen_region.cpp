// SeenRegion, the cells (and their sides) that the camera's first hits and their gathers read,
// and the photon filter built on it (PhotonRadianceSettings::keeps): a roof's top in the cell
// of the ceiling seen under it is not seen, dilation does not turn a cell's seen side over,
// the estimate keeps the sky's straight photons only where the gathers read, and the sphere of
// what the gathers read holds the room, not the ground outside.

#include "voxcone/accel/hbvh.h"
#include "voxcone/photon/photon_radiance.h"
#include "voxcone/photon/seen_region.h"
#include "voxcone/scene/scene.h"

#include "../support/test_scenes.h"

#include <gtest/gtest.h>

#include <memory>
#include <string>

namespace voxcone {
namespace {

/// A closed 4 x 3 x 4 m room ([0, 4] x [0, 3] x [0, 4], walls without thickness, facing in),
/// under a 6 x 6 roof at y = 3.1 facing up, on a 20 x 20 ground at y = -0.5; the camera inside.
/// The scene's lower corner is (-10, -0.5, -10), so with 0.5 m cells the ceiling (y = 3) and
/// the roof's top (y = 3.1) share their cells.
Scene roofedRoom() {
  const std::string json = R"({
    "camera": {"position": [2, 1.5, 0.5], "target": [2, 2.2, 3.5], "up": [0, 1, 0], "fov_y_deg": 80},
    "render": {"width": 32, "height": 32, "spp": 1},
    "materials": {"wall": {"type": "lambertian", "albedo": 0.5}},
    "shapes": [)" + test::boxQuads(Vec3(0.0f), Vec3(4.0f, 3.0f, 4.0f), "wall", true) + R"(,
      {"type": "quad", "material": "wall", "vertices": [[-1, 3.1, -1], [-1, 3.1, 5], [5, 3.1, 5], [5, 3.1, -1]]},
      {"type": "quad", "material": "wall",
       "vertices": [[-10, -0.5, -10], [-10, -0.5, 10], [10, -0.5, 10], [10, -0.5, -10]]}],
    "lights": [{"type": "environment", "radiance": 1}]
  })";
  return parseScene(json, "roofed-room", ".");
}

Photon photonAt(const Vec3& position, const Vec3& normal, int bounces, bool fromSky) {
  Photon p;
  p.position = position;
  p.normal = normal;
  p.incident = normal;
  p.power = Vec3(1.0f);
  p.bounces = uint8_t(bounces);
  p.fromEnvironment = fromSky ? 1 : 0;
  return p;
}

TEST(SeenRegion, ARoofAboveASeenCeilingIsNotSeenEvenAfterDilation) {
  const Scene scene = roofedRoom();
  const Hbvh accel(scene);
  SeenRegion region(scene, accel, 32, 32, 0.5f, 32, 32, 16);
  ASSERT_GT(region.cells(), 0u);
  const Vec3 ceiling(2.1f, 3.0f, 2.1f), roof(2.1f, 3.1f, 2.1f), ground(8.0f, -0.5f, 8.0f);
  const Vec3 up(0.0f, 1.0f, 0.0f);
  for (int pass = 0; pass < 2; ++pass) {
    SCOPED_TRACE(pass ? "dilated" : "as seen");
    EXPECT_TRUE(region.contains(ceiling, -up));
    EXPECT_FALSE(region.contains(roof, up));  // the same cell, the other side
    EXPECT_TRUE(region.holdsCell(roof));
    EXPECT_FALSE(region.holdsCell(ground));
    EXPECT_FALSE(region.contains(ground, up));
    region.dilate();
  }
  // Dilation reaches the cells around the seen ones on every side but the opposite one: a
  // point a cell under the ceiling, facing sideways, is held.
  EXPECT_TRUE(region.contains(Vec3(2.1f, 2.6f, 2.1f), Vec3(1.0f, 0.0f, 0.0f)));
}

TEST(SeenRegion, TheEstimateKeepsWhatTheGathersCanRead) {
  const Scene scene = roofedRoom();
  const Hbvh accel(scene);
  auto region = std::make_shared<SeenRegion>(scene, accel, 32, 32, 0.5f, 32, 32, 16);
  region->dilate();
  const Vec3 up(0.0f, 1.0f, 0.0f);
  const Photon ceilingBounced = photonAt(Vec3(2.1f, 3.0f, 2.1f), -up, 1, true);
  const Photon roofBounced = photonAt(Vec3(2.1f, 3.1f, 2.1f), up, 1, true);
  const Photon roofFromSky = photonAt(Vec3(2.1f, 3.1f, 2.1f), up, 0, true);
  const Photon floorFromSky = photonAt(Vec3(2.1f, 0.0f, 2.1f), up, 0, true);
  const Photon floorFromLamp = photonAt(Vec3(2.1f, 0.0f, 2.1f), up, 0, false);
  const Photon groundBounced = photonAt(Vec3(8.0f, -0.5f, 8.0f), up, 2, true);
  const Photon groundFromSky = photonAt(Vec3(8.0f, -0.5f, 8.0f), up, 0, true);

  PhotonRadianceSettings all;  // no region, every photon
  for (const Photon& p : {ceilingBounced, roofBounced, roofFromSky, floorFromSky, floorFromLamp, groundFromSky})
    EXPECT_TRUE(all.keeps(p));

  PhotonRadianceSettings bounced;  // direct light by shadow rays
  bounced.indirectOnly = true;
  EXPECT_TRUE(bounced.keeps(roofBounced));
  EXPECT_FALSE(bounced.keeps(floorFromSky));
  EXPECT_FALSE(bounced.keeps(floorFromLamp));

  PhotonRadianceSettings s;  // the lamps by shadow rays, the sky by its photons, the region
  s.indirectOnly = true;
  s.skyDirect = true;
  s.region = region;
  EXPECT_TRUE(s.keeps(ceilingBounced));
  EXPECT_FALSE(s.keeps(roofBounced));  // a seen cell, a side no gather reads
  EXPECT_FALSE(s.keeps(roofFromSky));
  EXPECT_TRUE(s.keeps(floorFromSky));  // the sky's own, where the gathers read
  EXPECT_FALSE(s.keeps(floorFromLamp));
  EXPECT_TRUE(s.keeps(groundBounced));   // a cell the region does not read: it may be of use
  EXPECT_FALSE(s.keeps(groundFromSky));  // but not the sky's straight photons there
  // Where the sky's photons are not kept, a cone's hit takes the sky by a shadow ray
  // (keepsSky): the ground outside, the roof; and everywhere without skyDirect.
  EXPECT_TRUE(s.keepsSky(floorFromSky.position, up));
  EXPECT_FALSE(s.keepsSky(groundFromSky.position, up));
  EXPECT_FALSE(s.keepsSky(roofFromSky.position, up));
  EXPECT_FALSE(bounced.keepsSky(floorFromSky.position, up));
  // count() takes the kept photons in seen cells.
  EXPECT_EQ(region->count({ceilingBounced, roofBounced, floorFromSky, floorFromLamp, groundBounced}, s), 2u);
}

TEST(SeenRegion, TheReadSphereHoldsTheRoomNotTheGroundOutside) {
  const Scene scene = roofedRoom();
  const Hbvh accel(scene);
  const Sphere s = SeenRegion::readSphere(scene, accel, 32, 32, 0.9, 32, 32, 16);
  ASSERT_GT(s.radius, 0.0f);
  for (int a = 0; a < 3; ++a) {
    EXPECT_GE(s.center[a], 0.0f) << a;
    EXPECT_LE(s.center[a], a == 1 ? 3.0f : 4.0f) << a;
  }
  // Every point of the room lies within its half diagonal (3.2 m) of any point inside it ...
  EXPECT_LT(s.radius, 2.0f * 3.2f);
  // ... and far less than the scene's sphere (the ground), which the whole disc would cover.
  EXPECT_LT(s.radius, 0.5f * scene.boundingSphere().radius);
  const Sphere all = SeenRegion::readSphere(scene, accel, 32, 32, 1.0, 32, 32, 16);
  EXPECT_GE(all.radius, s.radius);
  // Nothing hit: no sphere.
  const Scene empty = parseScene(R"({"camera": {"position": [0, 0, 5], "target": [0, 0, 0]},
    "materials": {"m": {"type": "lambertian", "albedo": 0.5}},
    "shapes": [{"type": "quad", "material": "m", "vertices": [[0, 0, 10], [0, 1, 10], [1, 1, 10], [1, 0, 10]]}],
    "lights": [{"type": "point", "position": [0, 0, 12], "intensity": 1}]})", "behind", ".");
  const Hbvh emptyAccel(empty);
  EXPECT_LT(SeenRegion::readSphere(empty, emptyAccel, 16, 16, 0.9, 8, 8, 4).radius, 0.0f);
}

}  // namespace
}  // namespace voxcone
