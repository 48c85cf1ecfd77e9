#include "mmrl/grid.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace mmrl {

namespace {

// The sensors' world positions for a character at (x, z, yaw): one sincos, then the same
// arithmetic for every sensor, so the grid map and the brute-force map test identical points.
struct SensorLattice {
  float x0, z0;       // world position of sensor (0, 0)
  float col_x, col_z; // world step per column (character +X * pitch)
  float row_x, row_z; // world step per row (character +Z * pitch)
  Vec2 at(int row, int col) const {
    return Vec2(x0 + static_cast<float>(col) * col_x + static_cast<float>(row) * row_x,
                z0 + static_cast<float>(col) * col_z + static_cast<float>(row) * row_z);
  }
};

SensorLattice sensor_lattice(const ObstacleFieldConfig& cfg, float x, float z, float yaw) {
  const float pitch = cfg.sensor_size / kMapSide;
  const float c = std::cos(yaw), s = std::sin(yaw);
  // Character axes in world (math.hpp): X_c = (c, -s), Z_c = (s, c).
  const float lx0 = 0.5f * pitch - 0.5f * cfg.sensor_size;
  const float lz0 = 0.5f * pitch - 0.5f * cfg.sensor_size + cfg.sensor_forward;
  SensorLattice l;
  l.x0 = x + c * lx0 + s * lz0;
  l.z0 = z - s * lx0 + c * lz0;
  l.col_x = c * pitch;
  l.col_z = -s * pitch;
  l.row_x = s * pitch;
  l.row_z = c * pitch;
  return l;
}

}  // namespace

ObstacleField::ObstacleField(int num_envs, const ObstacleFieldConfig& config) : config_(config), num_envs_(num_envs) {
  if (num_envs < 1) throw std::invalid_argument("num_envs must be >= 1");
  if (config.num_obstacles < 0 || config.num_obstacles > 30000)
    throw std::invalid_argument("num_obstacles must be between 0 and 30000");
  if (!(config.square_half > 0) || !(config.min_side > 0) || !(config.max_side >= config.min_side) ||
      !(config.cell_size > 0) || !(config.max_margin >= 0) || !(config.sensor_size > 0) ||
      !std::isfinite(config.sensor_forward) || !std::isfinite(config.max_side) || !std::isfinite(config.square_half))
    throw std::invalid_argument(
        "obstacle field: square_half, min_side, cell_size and sensor_size must be positive, max_side >= min_side, "
        "max_margin >= 0, all finite");
  const size_t slots = static_cast<size_t>(num_envs) * config.num_obstacles;
  count_.assign(num_envs, 0);
  generation_.assign(num_envs, 0);
  for (auto* v : {&cx_, &cz_, &vx_, &vz_, &hx_, &hz_, &angle_, &cos_, &sin_, &ex_, &ez_}) v->assign(slots, 0.0f);
  stamp_.assign(slots, 0);
  query_id_.assign(num_envs, 0);
  // A rotated rectangle's world box half extent is at most half its diagonal.
  const float max_extent = 0.5f * std::sqrt(2.0f) * config.max_side + config.max_margin;
  grid_half_ = config.square_half + max_extent + 0.01f;
  cells_ = static_cast<int>(std::ceil(2.0f * grid_half_ / config.cell_size));
  if (cells_ > 4096) throw std::invalid_argument("obstacle grid would exceed 4096 x 4096 cells: raise cell_size");
  const int span = static_cast<int>(std::floor(2.0f * max_extent / config.cell_size)) + 2;
  item_capacity_ = std::max(1, config.num_obstacles * span * span);
  cell_start_.assign(static_cast<size_t>(num_envs) * (static_cast<size_t>(cells_) * cells_ + 1), 0);
  cell_items_.assign(static_cast<size_t>(num_envs) * item_capacity_, 0);
}

void ObstacleField::finish_obstacle(size_t a) {
  cos_[a] = std::cos(angle_[a]);
  sin_[a] = std::sin(angle_[a]);
  const float c = std::abs(cos_[a]), s = std::abs(sin_[a]);
  ex_[a] = c * hx_[a] + s * hz_[a];
  ez_[a] = s * hx_[a] + c * hz_[a];
}

bool ObstacleField::contains(int env, int k, float x, float z) const {
  const size_t a = at(env, k);
  const float dx = x - cx_[a], dz = z - cz_[a];
  const float u = cos_[a] * dx - sin_[a] * dz, v = sin_[a] * dx + cos_[a] * dz;
  return std::abs(u) <= hx_[a] && std::abs(v) <= hz_[a];
}

float ObstacleField::distance(int env, int k, float x, float z) const {
  const size_t a = at(env, k);
  const float dx = x - cx_[a], dz = z - cz_[a];
  const float u = cos_[a] * dx - sin_[a] * dz, v = sin_[a] * dx + cos_[a] * dz;
  const float du = std::max(std::abs(u) - hx_[a], 0.0f), dv = std::max(std::abs(v) - hz_[a], 0.0f);
  return std::sqrt(du * du + dv * dv);
}

void ObstacleField::spawn(int env, Rng& rng, float max_speed, const ClearDisc* clear, int num_clear) {
  const float h = config_.square_half;
  const int n = config_.num_obstacles;
  ++generation_[env];
  count_[env] = n;
  for (int k = 0; k < n; ++k) {
    const size_t a = at(env, k);
    bool placed = false;
    for (int attempt = 0; attempt < 1000 && !placed; ++attempt) {
      hx_[a] = 0.5f * rng.uniform(config_.min_side, config_.max_side);
      hz_[a] = 0.5f * rng.uniform(config_.min_side, config_.max_side);
      angle_[a] = rng.uniform(0.0f, kPi);
      cx_[a] = rng.uniform(-h, h);
      cz_[a] = rng.uniform(-h, h);
      finish_obstacle(a);
      placed = true;
      for (int d = 0; d < num_clear && placed; ++d)
        if (distance(env, k, clear[d].x, clear[d].z) <= clear[d].radius) placed = false;
    }
    if (!placed) {  // a 1 cm square in the corner farthest from the discs
      float best = -1;
      for (int corner = 0; corner < 4; ++corner) {
        const float x = (corner & 1) ? h : -h, z = (corner & 2) ? h : -h;
        float nearest = 1e30f;
        for (int d = 0; d < num_clear; ++d) nearest = std::min(nearest, std::hypot(x - clear[d].x, z - clear[d].z));
        if (nearest > best) best = nearest, cx_[a] = x, cz_[a] = z;
      }
      hx_[a] = hz_[a] = 0.005f;
      angle_[a] = 0;
      finish_obstacle(a);
    }
    const float heading = rng.uniform(-kPi, kPi), speed = rng.uniform(0.0f, max_speed);
    vx_[a] = speed * std::cos(heading);
    vz_[a] = speed * std::sin(heading);
  }
}

void ObstacleField::set(int env, int n, const float* centres, const float* half_sizes, const float* angles,
                        const float* velocities) {
  if (n < 0 || n > config_.num_obstacles) throw std::invalid_argument("obstacle count exceeds the field's capacity");
  // The grid's bounds and item capacity assume these limits; refuse rather than overflow.
  const float h = config_.square_half, side = 0.5f * config_.max_side;
  for (int k = 0; k < n; ++k) {
    if (!(std::abs(centres[2 * k]) <= h) || !(std::abs(centres[2 * k + 1]) <= h))
      throw std::invalid_argument("obstacle centres must lie in the square [-square_half, square_half]^2");
    if (!(half_sizes[2 * k] >= 0 && half_sizes[2 * k] <= side) || !(half_sizes[2 * k + 1] >= 0 && half_sizes[2 * k + 1] <= side))
      throw std::invalid_argument("obstacle half sizes must be in [0, max_side / 2]");
  }
  ++generation_[env];
  count_[env] = n;
  for (int k = 0; k < n; ++k) {
    const size_t a = at(env, k);
    cx_[a] = centres[2 * k];
    cz_[a] = centres[2 * k + 1];
    hx_[a] = half_sizes[2 * k];
    hz_[a] = half_sizes[2 * k + 1];
    angle_[a] = angles[k];
    vx_[a] = velocities[2 * k];
    vz_[a] = velocities[2 * k + 1];
    finish_obstacle(a);
  }
}

namespace {
// One frame of one centre coordinate c (meters) moving at v (m/s) for dt seconds in
// [-h, h]: a centre that crosses the border is mirrored back inside and v flips (a frame
// is far shorter than the square, so once is enough).
inline void bounce_step(float& c, float& v, float dt, float h) {
  float x = c + v * dt;
  if (x > h) x = 2 * h - x, v = -v;
  else if (x < -h) x = -2 * h - x, v = -v;
  c = x;
}
}  // namespace

void ObstacleField::move(int env, float dt) {
  ++generation_[env];
  const float h = config_.square_half;
  const size_t b = at(env, 0), e = b + count_[env];
  for (size_t a = b; a < e; ++a) {
    bounce_step(cx_[a], vx_[a], dt, h);
    bounce_step(cz_[a], vz_[a], dt, h);
  }
}

void ObstacleField::moved(int env, int frames, float dt, float* centres, float* velocities) const {
  const float h = config_.square_half;
  for (int k = 0; k < count_[env]; ++k) {
    const size_t a = at(env, k);
    float x = cx_[a], z = cz_[a], vx = vx_[a], vz = vz_[a];
    for (int f = 0; f < frames; ++f) {
      bounce_step(x, vx, dt, h);
      bounce_step(z, vz, dt, h);
    }
    if (centres) centres[2 * k] = x, centres[2 * k + 1] = z;
    if (velocities) velocities[2 * k] = vx, velocities[2 * k + 1] = vz;
  }
}

void ObstacleField::path(int env, int k, int frames, float dt, float* xs, float* zs) const {
  const float h = config_.square_half;
  const size_t a = at(env, k);
  float x = cx_[a], z = cz_[a], vx = vx_[a], vz = vz_[a];
  for (int f = 0; f < frames; ++f) {
    bounce_step(x, vx, dt, h);
    bounce_step(z, vz, dt, h);
    xs[f] = x;
    zs[f] = z;
  }
}

void ObstacleField::cell_range(float a, float b, int* lo, int* hi) const {
  const float inv = 1.0f / config_.cell_size;
  *lo = std::max(0, static_cast<int>(std::floor((a + grid_half_) * inv)));
  *hi = std::min(cells_ - 1, static_cast<int>(std::floor((b + grid_half_) * inv)));
}

void ObstacleField::rebuild(int env, float margin) {
  margin = std::min(margin, config_.max_margin);
  const size_t ncell = static_cast<size_t>(cells_) * cells_;
  int32_t* start = &cell_start_[env * (ncell + 1)];
  int16_t* items = &cell_items_[static_cast<size_t>(env) * item_capacity_];
  std::fill(start, start + ncell + 1, 0);
  const size_t b = at(env, 0);
  const int n = count_[env];
  // Counting sort: count, inclusive prefix sum (start[c] = end of c), fill backwards.
  for (int pass = 0; pass < 2; ++pass) {
    for (int k = 0; k < n; ++k) {
      const size_t a = b + k;
      int x0, x1, z0, z1;
      cell_range(cx_[a] - ex_[a] - margin, cx_[a] + ex_[a] + margin, &x0, &x1);
      cell_range(cz_[a] - ez_[a] - margin, cz_[a] + ez_[a] + margin, &z0, &z1);
      for (int cz = z0; cz <= z1; ++cz)
        for (int cx = x0; cx <= x1; ++cx) {
          const size_t c = static_cast<size_t>(cz) * cells_ + cx;
          if (pass == 0) ++start[c];
          else items[--start[c]] = static_cast<int16_t>(k);
        }
    }
    if (pass == 0) {
      for (size_t c = 1; c < ncell; ++c) start[c] += start[c - 1];
      start[ncell] = start[ncell - 1];
    }
  }
}

bool ObstacleField::point_inside_any(int env, float x, float z) const {
  return disc_overlaps_any(env, x, z, 0.0f);
}

bool ObstacleField::disc_overlaps_any(int env, float x, float z, float radius) const {
  const float inv = 1.0f / config_.cell_size;
  const float gx = (x + grid_half_) * inv, gz = (z + grid_half_) * inv;
  if (!(gx >= 0 && gz >= 0 && gx < cells_ && gz < cells_)) return false;  // no obstacle reaches outside the grid
  const size_t ncell = static_cast<size_t>(cells_) * cells_;
  const int32_t* start = &cell_start_[env * (ncell + 1)];
  const int16_t* items = &cell_items_[static_cast<size_t>(env) * item_capacity_];
  const size_t c = static_cast<size_t>(gz) * cells_ + static_cast<size_t>(gx);
  const size_t b = at(env, 0);
  const float r2 = radius * radius;
  for (int32_t i = start[c]; i < start[c + 1]; ++i) {
    const size_t a = b + items[i];
    const float dx = x - cx_[a], dz = z - cz_[a];
    const float u = cos_[a] * dx - sin_[a] * dz, v = sin_[a] * dx + cos_[a] * dz;
    const float du = std::max(std::abs(u) - hx_[a], 0.0f), dv = std::max(std::abs(v) - hz_[a], 0.0f);
    if (du * du + dv * dv <= r2) return true;
  }
  return false;
}

namespace {
// Where a centre at c moving at v sits after dt in [-h, h] with mirror bounces (period 4h).
float bounced(float c, float v, float dt, float h) {
  if (!(h > 0)) return c;
  const float period = 4 * h;
  float q = std::fmod(c + v * dt + h, period);
  if (q < 0) q += period;
  if (q > 2 * h) q = period - q;
  return q - h;
}
}  // namespace

bool ObstacleField::disc_overlaps_any_ahead(int env, float x, float z, float radius, float dt) const {
  const float h = config_.square_half, r2 = radius * radius;
  const size_t b = at(env, 0), e = b + count_[env];
  for (size_t a = b; a < e; ++a) {
    const float dx = x - bounced(cx_[a], vx_[a], dt, h), dz = z - bounced(cz_[a], vz_[a], dt, h);
    const float u = cos_[a] * dx - sin_[a] * dz, v = sin_[a] * dx + cos_[a] * dz;
    const float du = std::max(std::abs(u) - hx_[a], 0.0f), dv = std::max(std::abs(v) - hz_[a], 0.0f);
    if (du * du + dv * dv <= r2) return true;
  }
  return false;
}

Vec2 ObstacleField::sensor_position(float x, float z, float yaw, int row, int col) const {
  return sensor_lattice(config_, x, z, yaw).at(row, col);
}

void ObstacleField::sensor_map(int env, float x, float z, float yaw, uint8_t* map) {
  std::fill(map, map + kMapCells, uint8_t{0});
  const SensorLattice lat = sensor_lattice(config_, x, z, yaw);
  const float pitch = config_.sensor_size / kMapSide, half = 0.5f * config_.sensor_size;
  // World box of the sensor square (its four corners), to pick grid cells.
  float wx0 = 1e30f, wx1 = -1e30f, wz0 = 1e30f, wz1 = -1e30f;
  for (int corner = 0; corner < 4; ++corner) {
    const float lx = (corner & 1) ? half : -half;
    const float lz = config_.sensor_forward + ((corner & 2) ? half : -half);
    const Vec2 w = local_to_world_xz(lx, lz, yaw);
    wx0 = std::min(wx0, x + w.x()), wx1 = std::max(wx1, x + w.x());
    wz0 = std::min(wz0, z + w.y()), wz1 = std::max(wz1, z + w.y());
  }
  int x0, x1, z0, z1;
  cell_range(wx0, wx1, &x0, &x1);
  cell_range(wz0, wz1, &z0, &z1);
  const size_t ncell = static_cast<size_t>(cells_) * cells_;
  const int32_t* start = &cell_start_[env * (ncell + 1)];
  const int16_t* items = &cell_items_[static_cast<size_t>(env) * item_capacity_];
  const size_t b = at(env, 0);
  const uint32_t qid = ++query_id_[env];
  if (qid == 0) std::fill(&stamp_[b], &stamp_[b] + config_.num_obstacles, 0u), query_id_[env] = 1;
  const uint32_t id = query_id_[env];
  const float inv_pitch = 1.0f / pitch;
  for (int cz = z0; cz <= z1; ++cz)
    for (int cx = x0; cx <= x1; ++cx) {
      const size_t c = static_cast<size_t>(cz) * cells_ + cx;
      for (int32_t i = start[c]; i < start[c + 1]; ++i) {
        const size_t a = b + items[i];
        if (stamp_[a] == id) continue;
        stamp_[a] = id;
        // Rasterize: the obstacle's box in the character frame -> the sensor rows and
        // columns it can cover; then the exact test on each of them.
        const Vec2 l = world_to_local_xz(cx_[a] - x, cz_[a] - z, yaw);
        const float rel = angle_[a] - yaw;
        const float rc = std::abs(std::cos(rel)), rs = std::abs(std::sin(rel));
        const float ex = rc * hx_[a] + rs * hz_[a] + 1e-3f, ez = rs * hx_[a] + rc * hz_[a] + 1e-3f;
        const int c0 = std::max(0, static_cast<int>(std::ceil((l.x() - ex + half) * inv_pitch - 0.5f)));
        const int c1 = std::min(kMapSide - 1, static_cast<int>(std::floor((l.x() + ex + half) * inv_pitch - 0.5f)));
        const float zb = half - config_.sensor_forward;
        const int r0 = std::max(0, static_cast<int>(std::ceil((l.y() - ez + zb) * inv_pitch - 0.5f)));
        const int r1 = std::min(kMapSide - 1, static_cast<int>(std::floor((l.y() + ez + zb) * inv_pitch - 0.5f)));
        for (int row = r0; row <= r1; ++row)
          for (int col = c0; col <= c1; ++col) {
            uint8_t& cell = map[row * kMapSide + col];
            if (cell) continue;
            const Vec2 p = lat.at(row, col);
            const float dx = p.x() - cx_[a], dz = p.y() - cz_[a];
            const float u = cos_[a] * dx - sin_[a] * dz, v = sin_[a] * dx + cos_[a] * dz;
            if (std::abs(u) <= hx_[a] && std::abs(v) <= hz_[a]) cell = 1;
          }
      }
    }
}

void ObstacleField::sensor_map_bruteforce(int env, float x, float z, float yaw, uint8_t* map) const {
  const SensorLattice lat = sensor_lattice(config_, x, z, yaw);
  for (int row = 0; row < kMapSide; ++row)
    for (int col = 0; col < kMapSide; ++col) {
      const Vec2 p = lat.at(row, col);
      uint8_t hit = 0;
      for (int k = 0; k < count_[env] && !hit; ++k) hit = contains(env, k, p.x(), p.y());
      map[row * kMapSide + col] = hit;
    }
}

}  // namespace mmrl
