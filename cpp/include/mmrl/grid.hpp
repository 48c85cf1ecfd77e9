// Moving rectangular obstacles for a batch of environments, a uniform-grid broadphase over
// them, 16 x 16 binary sensor maps in the character frame, and point / body-disc queries.
//
// Spaces and units: world space, meters, seconds; horizontal plane (x, z), Y up. Each
// environment's obstacle square is centred on the world origin (the character's start).
//
// Obstacles (choices the paper leaves open; see also obstacles_env.hpp):
//   - shape: oriented (rotated) rectangles. Obstacle k has a centre (x, z), half sizes
//     (hx, hz) along its own X / Z axes and an angle: the rectangle's local frame is the
//     world rotated by `angle` about +Y, with the same convention as a character yaw
//     (math.hpp: local = world_to_local_xz(p - c, angle)). Angles are uniform in [0, pi)
//     (a rectangle is symmetric under a half turn).
//   - size: each side independently uniform in [min_side, max_side] (default 0.25 .. 3 m),
//     so no obstacle exceeds 3 x 3 m and none is a sliver thinner than the sensor pitch.
//   - motion: constant velocity, direction uniform on the circle, speed uniform in
//     [0, max_speed]. The centre bounces off the square's border (|x|, |z| <= half): a
//     centre that crosses the border is mirrored back inside and that velocity component
//     flips, so centres never leave the square (the rectangle may overhang by its extent).
//   - inside: a point p is inside obstacle k iff |u| <= hx and |v| <= hz, (u, v) = p in the
//     obstacle frame. A body disc of radius r overlaps k iff the distance from its centre
//     to the rectangle is <= r.
//
// Broadphase: per environment, a uniform grid of square cells over the square plus the
// largest obstacle extent; each obstacle is entered (counting sort, CSR arrays) in every
// cell its axis-aligned box, inflated by a margin, overlaps. The grid is rebuilt once per RL
// step with margin = body radius + the farthest an obstacle can move in one step, so one
// build answers the step's hit queries, every played frame's collision test and the
// sensor map at the step's end, all with exact tests on the current positions.
//
// Sensor map: 16 x 16 point sensors on a square of side sensor_size (6 m) in the character
// frame. Sensor (row, col) sits at
//   x = (col + 0.5) * pitch - size / 2            (X, character's left, increases with col)
//   z = (row + 0.5) * pitch - size / 2 + forward  (Z, forward, increases with row)
// pitch = size / 16. It reads 1 where it is inside any obstacle. Map arrays are row-major
// [row][col]. `forward` shifts the square ahead of the character (see obstacles_env.hpp).
#pragma once

#include <cstdint>
#include <vector>

#include "mmrl/math.hpp"
#include "mmrl/rng.hpp"

namespace mmrl {

constexpr int kMapSide = 16;
constexpr int kMapCells = kMapSide * kMapSide;

struct ObstacleFieldConfig {
  int num_obstacles = 100;
  float square_half = 10.0f;   // obstacle centres stay in [-h, h]^2 (meters)
  float min_side = 0.25f;      // rectangle sides uniform in [min_side, max_side] (meters)
  float max_side = 3.0f;
  float cell_size = 1.0f;      // broadphase cell side (meters)
  float max_margin = 1.0f;     // the largest rebuild margin that will be asked for (meters)
  float sensor_size = 6.0f;    // side of the sensor square (meters)
  float sensor_forward = 1.5f; // centre of the sensor square ahead of the character (meters)
};

// A disc that a newly spawned obstacle must keep clear of (distance > radius).
struct ClearDisc {
  float x = 0, z = 0, radius = 0;
};

// Obstacles of num_envs environments in structure-of-arrays form (env-major, num_obstacles
// per env), plus each environment's grid. Environments are independent: calls for
// different envs may run on different threads.
class ObstacleField {
 public:
  ObstacleField(int num_envs, const ObstacleFieldConfig& config);

  const ObstacleFieldConfig& config() const { return config_; }
  int num_envs() const { return num_envs_; }
  int capacity() const { return config_.num_obstacles; }
  int count(int env) const { return count_[env]; }
  // Changes each time env's obstacles change (spawn, set, move): a cache of anything derived
  // from them (the path filter's prepared obstacles) is still good while it stays the same.
  uint64_t generation(int env) const { return generation_[env]; }

  // Draws env's obstacles (see the header comment): positions uniform in the square,
  // redrawn while they come within any of the clear discs (at most 1000 tries each; an
  // obstacle that still fails becomes a 1 cm square in the farthest corner from the discs).
  void spawn(int env, Rng& rng, float max_speed, const ClearDisc* clear, int num_clear);
  // Replaces env's obstacles (count <= capacity): centres, half sizes (n x 2), angles (n),
  // velocities (n x 2). Throws std::invalid_argument unless every centre is in the square
  // and every half size in [0, max_side / 2] (the grid is sized for those).
  void set(int env, int n, const float* centres, const float* half_sizes, const float* angles,
           const float* velocities);
  // Advances env's obstacles by dt seconds with bouncing.
  void move(int env, float dt);
  // Env's centres and velocities (count(env) x 2 each, either may be null) after `frames`
  // calls of move(env, dt), without moving anything: the same arithmetic, bit for bit.
  void moved(int env, int frames, float dt, float* centres, float* velocities) const;
  // Obstacle k of env's centre after each of the next `frames` calls of move(env, dt), without
  // moving anything (the same arithmetic): x[f], z[f] after f + 1 moves, f < frames.
  void path(int env, int k, int frames, float dt, float* x, float* z) const;
  // Rebuilds env's grid with the given margin (meters, <= config.max_margin).
  void rebuild(int env, float margin);

  // Exact queries on the current positions, through the grid (rebuilt with a margin that
  // covers the motion since the last rebuild, plus r for disc queries).
  bool point_inside_any(int env, float x, float z) const;
  bool disc_overlaps_any(int env, float x, float z, float radius) const;
  // Whether a disc at (x, z) overlaps any obstacle where it will be dt seconds from now
  // (constant velocity, mirrored at the square's border as move() does). Tests every
  // obstacle (no grid: the grid's margin covers one step's motion, not dt).
  bool disc_overlaps_any_ahead(int env, float x, float z, float radius, float dt) const;
  // Writes env's sensor map (kMapCells bytes, 0/1) for a character at (x, z, yaw).
  void sensor_map(int env, float x, float z, float yaw, uint8_t* map);
  // The same map by testing every sensor against every obstacle (the tests' reference).
  void sensor_map_bruteforce(int env, float x, float z, float yaw, uint8_t* map) const;
  // World (x, z) of sensor (row, col) for a character at (x, z, yaw).
  Vec2 sensor_position(float x, float z, float yaw, int row, int col) const;

  // Obstacle k of env (k < count(env)).
  bool contains(int env, int k, float x, float z) const;
  float distance(int env, int k, float x, float z) const;  // 0 inside
  Vec2 centre(int env, int k) const { return Vec2(cx_[at(env, k)], cz_[at(env, k)]); }
  Vec2 half_size(int env, int k) const { return Vec2(hx_[at(env, k)], hz_[at(env, k)]); }
  float angle(int env, int k) const { return angle_[at(env, k)]; }
  Vec2 velocity(int env, int k) const { return Vec2(vx_[at(env, k)], vz_[at(env, k)]); }
  // (cos, sin) of obstacle k's angle: a world offset d is (cos d.x - sin d.z, sin d.x + cos d.z)
  // in its frame (contains, distance).
  Vec2 rotation(int env, int k) const { return Vec2(cos_[at(env, k)], sin_[at(env, k)]); }

 private:
  size_t at(int env, int k) const { return static_cast<size_t>(env) * config_.num_obstacles + k; }
  void finish_obstacle(size_t a);  // derived fields (cos, sin, box extents) of slot a
  // Cell range [lo, hi] (inclusive, clamped) covering [a, b] along one axis.
  void cell_range(float a, float b, int* lo, int* hi) const;

  ObstacleFieldConfig config_;
  int num_envs_;
  std::vector<int> count_;
  std::vector<uint64_t> generation_;
  // Per obstacle slot: centre, velocity, half sizes, angle, cos/sin, world box half extents.
  std::vector<float> cx_, cz_, vx_, vz_, hx_, hz_, angle_, cos_, sin_, ex_, ez_;
  // Grid: cells_ per side over [-grid_half_, grid_half_]^2; per env cell_start_ (cells + 1)
  // and cell_items_ (item_capacity_ obstacle indices).
  int cells_ = 0;
  float grid_half_ = 0;
  int item_capacity_ = 0;
  std::vector<int32_t> cell_start_;
  std::vector<int16_t> cell_items_;
  // Per obstacle slot, the last sensor query that visited it (dedups grid candidates).
  std::vector<uint32_t> stamp_;
  std::vector<uint32_t> query_id_;  // per env
};

}  // namespace mmrl
