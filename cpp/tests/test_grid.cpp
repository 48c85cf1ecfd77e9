// ObstacleField: grid sensor maps and queries against brute force, bouncing, spawning.
#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>
#include <vector>

#include "mmrl/grid.hpp"

namespace mmrl {
namespace {

ObstacleFieldConfig small_config() {
  ObstacleFieldConfig c;
  c.max_margin = 0.6f;
  return c;
}

TEST(ObstacleField, RefusesBadConfig) {
  ObstacleFieldConfig c;
  EXPECT_THROW(ObstacleField(0, c), std::invalid_argument);
  c.min_side = 2, c.max_side = 1;
  EXPECT_THROW(ObstacleField(1, c), std::invalid_argument);
  c = ObstacleFieldConfig{};
  c.cell_size = 0;
  EXPECT_THROW(ObstacleField(1, c), std::invalid_argument);
  c = ObstacleFieldConfig{};
  c.sensor_size = NAN;
  EXPECT_THROW(ObstacleField(1, c), std::invalid_argument);
}

TEST(ObstacleField, SetRefusesObstaclesTheGridCannotHold) {
  ObstacleField field(1, small_config());
  const float c[2] = {0, 0}, big[2] = {1.6f, 0.1f}, ok[2] = {1.5f, 0.1f}, a[1] = {0}, v[2] = {0, 0};
  const float far[2] = {10.5f, 0};
  EXPECT_THROW(field.set(0, 1, c, big, a, v), std::invalid_argument);
  EXPECT_THROW(field.set(0, 1, far, ok, a, v), std::invalid_argument);
  EXPECT_THROW(field.set(0, 101, c, ok, a, v), std::invalid_argument);
  EXPECT_NO_THROW(field.set(0, 1, c, ok, a, v));
}

TEST(ObstacleField, SensorMapMatchesBruteForceOnRandomRotatedScenes) {
  const int envs = 3;
  ObstacleField field(envs, small_config());
  Rng rng(7, 0);
  int ones = 0;
  for (int trial = 0; trial < 200; ++trial) {
    const int e = trial % envs;
    field.spawn(e, rng, 0.5f, nullptr, 0);
    // Move a few frames so the grid margin matters, then rebuild as the env does.
    field.rebuild(e, 0.6f);
    for (int f = 0; f < 6; ++f) field.move(e, 1.0f / 30.0f);
    const float x = rng.uniform(-12, 12), z = rng.uniform(-12, 12), yaw = rng.uniform(-kPi, kPi);
    uint8_t fast[kMapCells], slow[kMapCells];
    field.sensor_map(e, x, z, yaw, fast);
    field.sensor_map_bruteforce(e, x, z, yaw, slow);
    for (int k = 0; k < kMapCells; ++k) ASSERT_EQ(fast[k], slow[k]) << "trial " << trial << " cell " << k;
    for (int k = 0; k < kMapCells; ++k) ones += slow[k];
    // Point and disc queries against every obstacle.
    for (int q = 0; q < 50; ++q) {
      const float px = x + rng.uniform(-4, 4), pz = z + rng.uniform(-4, 4);
      bool inside = false, near = false;
      for (int k = 0; k < field.count(e); ++k) {
        inside = inside || field.contains(e, k, px, pz);
        near = near || field.distance(e, k, px, pz) <= 0.25f;
      }
      ASSERT_EQ(field.point_inside_any(e, px, pz), inside);
      ASSERT_EQ(field.disc_overlaps_any(e, px, pz, 0.25f), near);
    }
  }
  EXPECT_GT(ones, 200 * kMapCells / 10);  // the scenes are not trivially empty
}

TEST(ObstacleField, SensorLayoutRowIsForwardColIsLeft) {
  ObstacleField field(1, small_config());
  // One 0.2 m square 2 m ahead and 1 m to the left of a character at the origin facing +X
  // (yaw = pi/2: forward = +X, left = -Z).
  const float c[2] = {2.0f, -1.0f}, h[2] = {0.12f, 0.12f}, a[1] = {0.0f}, v[2] = {0, 0};
  field.set(0, 1, c, h, a, v);
  field.rebuild(0, 0.1f);
  uint8_t map[kMapCells];
  field.sensor_map(0, 0, 0, kPi / 2, map);
  const float pitch = 6.0f / 16;
  // Sensor covering local (x = 1 left, z = 2 forward): col = (1 + 3) / pitch, row = (2 - 1.5 + 3) / pitch.
  const int col = static_cast<int>((1.0f + 3.0f) / pitch), row = static_cast<int>((2.0f - 1.5f + 3.0f) / pitch);
  int total = 0;
  for (int k = 0; k < kMapCells; ++k) total += map[k];
  const Vec2 p = field.sensor_position(0, 0, kPi / 2, row, col);
  EXPECT_EQ(map[row * kMapSide + col], 1);
  EXPECT_EQ(total, 1);
  // The sensor's world position is within half a pitch diagonal of the obstacle centre.
  EXPECT_LT(std::hypot(p.x() - 2.0f, p.y() + 1.0f), pitch);
}

TEST(ObstacleField, BouncingKeepsCentresInTheSquare) {
  ObstacleFieldConfig cfg = small_config();
  cfg.max_margin = 1.0f;
  ObstacleField field(2, cfg);
  Rng rng(3, 1);
  for (int e = 0; e < 2; ++e) field.spawn(e, rng, 2.0f, nullptr, 0);
  bool flipped = false;
  std::vector<float> vx0;
  for (int k = 0; k < field.count(0); ++k) vx0.push_back(field.velocity(0, k).x());
  for (int f = 0; f < 30 * 60; ++f)
    for (int e = 0; e < 2; ++e) {
      field.move(e, 1.0f / 30);
      for (int k = 0; k < field.count(e); ++k) {
        ASSERT_LE(std::abs(field.centre(e, k).x()), cfg.square_half);
        ASSERT_LE(std::abs(field.centre(e, k).y()), cfg.square_half);
      }
    }
  for (int k = 0; k < field.count(0); ++k) {
    const Vec2 v = field.velocity(0, k);
    EXPECT_NEAR(std::abs(v.x()), std::abs(vx0[k]), 1e-6f);  // speeds are kept
    flipped = flipped || (v.x() * vx0[k] < 0);
  }
  EXPECT_TRUE(flipped);
}

TEST(ObstacleField, SpawnKeepsClearDiscsFree) {
  ObstacleField field(1, small_config());
  Rng rng(11, 0);
  for (int trial = 0; trial < 100; ++trial) {
    const ClearDisc discs[2] = {{0, 0, 0.75f}, {rng.uniform(-5, 5), rng.uniform(-5, 5), 0.5f}};
    field.spawn(0, rng, 0.5f, discs, 2);
    ASSERT_EQ(field.count(0), 100);
    for (int k = 0; k < field.count(0); ++k) {
      const Vec2 hs = field.half_size(0, k);
      ASSERT_LE(2 * hs.x(), 3.0f);
      ASSERT_GE(2 * hs.x(), 0.25f);
      ASSERT_LE(2 * hs.y(), 3.0f);
      ASSERT_LE(field.velocity(0, k).norm(), 0.5f + 1e-5f);
      for (const ClearDisc& d : discs) ASSERT_GT(field.distance(0, k, d.x, d.z), d.radius);
    }
  }
}

}  // namespace
}  // namespace mmrl
