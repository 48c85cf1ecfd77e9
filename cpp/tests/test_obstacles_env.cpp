// The moving-obstacles task (tasks/obstacles.hpp): frames played per step against a brute-force
// re-simulation, obstacles_after against stepping, seeding by index, and refused scenes.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "env_test_database.hpp"
#include "mmrl/tasks/obstacles.hpp"

namespace mmrl {
namespace {

using testing_db::database;
using testing_db::matcher;

constexpr int kObs = ObstacleVecEnv::kObsDim;

struct ObstacleBuffers {
  explicit ObstacleBuffers(int n)
      : obs(static_cast<size_t>(n) * kObs), final_obs(static_cast<size_t>(n) * kObs), rewards(n), ret(n),
        terminated(n), truncated(n), success(n), collision(n), hits(n), len(n) {}
  void step(ObstacleVecEnv& env, const std::vector<float>& actions) {
    env.step(actions.data(), obs.data(), rewards.data(), terminated.data(), truncated.data(), success.data(),
             collision.data(), hits.data(), final_obs.data(), ret.data(), len.data());
  }
  std::vector<float> obs, final_obs, rewards, ret;
  std::vector<uint8_t> terminated, truncated, success, collision;
  std::vector<int32_t> hits, len;
};

std::vector<float> random_actions(std::mt19937& gen, int n) {
  const Database& db = database();
  std::uniform_int_distribution<int> pick(0, db.num_frames - 31);
  std::normal_distribution<float> noise(0.0f, 0.5f);
  std::vector<float> a(static_cast<size_t>(n) * kTrajectoryDim);
  for (int i = 0; i < n; ++i) {
    int f = pick(gen);
    while (!db.valid[f]) f = pick(gen);
    const float* t = &db.normalized[static_cast<size_t>(f) * kFeatureDim + kPoseDim];
    for (int k = 0; k < kTrajectoryDim; ++k) a[i * kTrajectoryDim + k] = t[k] + noise(gen);
  }
  return a;
}

struct Scene {
  std::vector<float> centres, half_sizes, angles, velocities;
};

Scene scene_of(const ObstacleVecEnv& env, int i) {
  const int n = env.obstacle_count(i);
  Scene s{std::vector<float>(2 * n), std::vector<float>(2 * n), std::vector<float>(n), std::vector<float>(2 * n)};
  env.obstacles(i, s.centres.data(), s.half_sizes.data(), s.angles.data(), s.velocities.data());
  return s;
}

// Distance from (x, z) to rectangle k of a scene with centres c (the same rule as grid.hpp,
// written out: the point in the rectangle's frame, then the distance to the box).
float rect_distance(const Scene& s, const std::vector<float>& c, int k, float x, float z) {
  const float co = std::cos(s.angles[k]), si = std::sin(s.angles[k]);
  const float dx = x - c[2 * k], dz = z - c[2 * k + 1];
  const float u = co * dx - si * dz, v = si * dx + co * dz;
  const float du = std::max(std::abs(u) - s.half_sizes[2 * k], 0.0f);
  const float dv = std::max(std::abs(v) - s.half_sizes[2 * k + 1], 0.0f);
  return std::sqrt(du * du + dv * dv);
}

TEST(ObstacleVecEnv, LastStepFramesEqualsBruteForceResimulation) {
  const Database& db = database();
  ObstacleTaskConfig cfg;
  cfg.num_obstacles = 60;
  cfg.obstacle_max_speed = 2.0f;  // fast obstacles: collisions land anywhere inside a step
  cfg.target_half_extent = 1.5f;  // near targets: successes too
  const int n = 16;
  ObstacleVecEnv env(db, matcher(), n, cfg, 2);
  ObstacleBuffers buf(n);
  env.reset(21, buf.obs.data());
  std::mt19937 gen(5);
  int mid_step_collisions = 0, mid_step_successes = 0, full_steps = 0;
  std::vector<int32_t> played(n);
  for (int t = 0; t < 60; ++t) {
    const std::vector<float> act = random_actions(gen, n);
    // Before the step: each env's state, its decision and its obstacles after k frames.
    std::vector<ObstacleEnvState> s0;
    std::vector<Scene> scene;
    std::vector<std::vector<std::vector<float>>> centres_after(n);
    for (int i = 0; i < n; ++i) {
      s0.push_back(env.state(i));
      scene.push_back(scene_of(env, i));
      for (int k = 1; k <= cfg.frames_per_step; ++k) {
        std::vector<float> c(2 * env.obstacle_count(i));
        env.obstacles_after(i, k, c.data(), nullptr);
        centres_after[i].push_back(c);
      }
    }
    buf.step(env, act);
    env.step_frames(played.data());
    for (int i = 0; i < n; ++i) {
      const int64_t j = decision_for_action(db, matcher(), s0[i].frame, &act[i * kTrajectoryDim], env.action_low(),
                                          env.action_high());
      RootState root = s0[i].root;
      int expected = cfg.frames_per_step;
      bool collision = false, success = false;
      for (int k = 0; k < cfg.frames_per_step; ++k) {
        root_advance(root, &db.root_deltas[static_cast<size_t>(j + k) * 3]);
        for (int o = 0; o < static_cast<int>(scene[i].angles.size()) && !collision; ++o)
          collision = rect_distance(scene[i], centres_after[i][k], o, root.x, root.z) <= cfg.body_radius;
        success = !collision && std::hypot(s0[i].target_x - root.x, s0[i].target_z - root.z) <= cfg.success_radius;
        if (collision || success) {
          expected = k + 1;
          break;
        }
      }
      ASSERT_EQ(played[i], expected) << "step " << t << " env " << i;
      ASSERT_EQ(buf.collision[i], collision);
      ASSERT_EQ(buf.success[i], success);
      ASSERT_EQ(buf.terminated[i], collision || success);
      mid_step_collisions += collision && expected < cfg.frames_per_step;
      mid_step_successes += success && expected < cfg.frames_per_step;
      full_steps += expected == cfg.frames_per_step;
    }
  }
  // The run covered steps cut short by either event and steps played in full.
  EXPECT_GE(mid_step_collisions, 5);
  EXPECT_GE(mid_step_successes, 2);
  EXPECT_GE(full_steps, 100);
}

TEST(ObstacleVecEnv, ObstaclesAfterEqualsStepping) {
  ObstacleTaskConfig cfg;
  cfg.num_obstacles = 8;
  ObstacleVecEnv env(database(), matcher(), 2, cfg, 1);
  ObstacleBuffers buf(2);
  env.reset(3, buf.obs.data());
  // Obstacles near the border of the 20 x 20 m square, moving fast along it and into it (so
  // several bounce within a few steps); the character at the origin walks at most ~3 m.
  const Scene hand{{9.7f, 8.0f, -9.9f, -8.0f, 8.0f, 9.95f, -8.5f, -9.6f, 0.0f, 9.0f, 9.0f, -9.0f, 9.9f, 9.9f, -9.0f, 9.0f},
                   std::vector<float>(16, 0.3f),
                   {0.1f, 0.5f, 1.0f, 2.0f, 0.0f, 0.3f, 1.2f, 2.9f},
                   {1.9f, 0.2f, -1.5f, 1.0f, 0.3f, 1.8f, -0.7f, -1.7f, 1.2f, 1.2f, -1.0f, -1.4f, 1.3f, 1.3f, -1.9f, 0.1f}};
  env.set_obstacles(1, 8, hand.centres.data(), hand.half_sizes.data(), hand.angles.data(), hand.velocities.data());
  env.set_target(1, -5.0f, -9.0f);
  const Scene start = scene_of(env, 1);
  std::vector<float> c(16), v(16);
  env.obstacles_after(1, 0, c.data(), v.data());
  EXPECT_EQ(c, start.centres);
  EXPECT_EQ(v, start.velocities);
  // Predicted at the start for the end of steps 1..6 (6 frames each).
  const int steps = 6;
  std::vector<std::vector<float>> pc(steps + 1, std::vector<float>(16)), pv(pc);
  for (int t = 1; t <= steps; ++t) env.obstacles_after(1, t * cfg.frames_per_step, pc[t].data(), pv[t].data());
  std::mt19937 gen(6);
  for (int t = 1; t <= steps; ++t) {
    buf.step(env, random_actions(gen, 2));
    ASSERT_EQ(buf.terminated[1] + buf.truncated[1], 0) << "the hand scene must not end the episode";
    const Scene now = scene_of(env, 1);
    EXPECT_EQ(pc[t], now.centres) << "step " << t;  // bit for bit
    EXPECT_EQ(pv[t], now.velocities) << "step " << t;
    EXPECT_EQ(now.half_sizes, start.half_sizes);
    EXPECT_EQ(now.angles, start.angles);
  }
  int flips = 0;
  for (int k = 0; k < 16; ++k) flips += (pv[steps][k] > 0) != (start.velocities[k] > 0);
  EXPECT_GE(flips, 6);  // bounces happened inside the predicted span
  EXPECT_THROW(env.obstacles_after(1, -1, c.data(), v.data()), std::invalid_argument);
}

TEST(ObstacleVecEnv, SeedingByIndexAndCurrentFrames) {
  ObstacleTaskConfig cfg;
  cfg.num_obstacles = 30;
  ObstacleVecEnv a(database(), matcher(), 2, cfg, 1), b(database(), matcher(), 4, cfg, 2);
  ObstacleBuffers ba(2), bb(4);
  a.reset(11, ba.obs.data());
  b.reset(11, bb.obs.data());
  std::mt19937 gen(7);
  for (int t = 0; t < 25; ++t) {
    std::vector<float> act = random_actions(gen, 4);
    bb.step(b, act);
    act.resize(2 * kTrajectoryDim);
    ba.step(a, act);
    std::vector<int64_t> fa(2), fb(4);
    a.current_frames(fa.data());
    b.current_frames(fb.data());
    for (int i = 0; i < 2; ++i) {
      ASSERT_EQ(0, std::memcmp(&ba.obs[i * kObs], &bb.obs[i * kObs], sizeof(float) * kObs)) << "step " << t;
      ASSERT_EQ(ba.rewards[i], bb.rewards[i]);
      ASSERT_EQ(ba.hits[i], bb.hits[i]);
      ASSERT_EQ(fa[i], fb[i]);
      ASSERT_EQ(fa[i], a.state(i).frame);
      const Scene sa = scene_of(a, i), sb = scene_of(b, i);
      ASSERT_EQ(sa.centres, sb.centres);
      ASSERT_EQ(sa.velocities, sb.velocities);
    }
  }
}

TEST(ObstacleVecEnv, RefusesBadScenesNamingTheArgument) {
  ObstacleTaskConfig cfg;
  cfg.num_obstacles = 4;
  ObstacleVecEnv env(database(), matcher(), 1, cfg, 1);
  const float c[2] = {1, 1}, h[2] = {0.5f, 0.5f}, a[1] = {0}, v[2] = {0.5f, 0};
  auto refused = [&](const float* cc, const float* hh, const float* aa, const float* vv, int n, const char* word) {
    try {
      env.set_obstacles(0, n, cc, hh, aa, vv);
      ADD_FAILURE() << "accepted; expected an error naming " << word;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(word), std::string::npos) << e.what();
    }
  };
  const float nan2[2] = {NAN, 0}, neg[2] = {-0.1f, 0.2f}, fast[2] = {3.0f, 0}, out[2] = {10.5f, 0}, big[2] = {1.6f, 0.2f};
  const float nan1[1] = {NAN};
  std::vector<float> many(10, 0.0f);
  refused(many.data(), many.data(), many.data(), many.data(), 5, "num_obstacles");
  refused(nan2, h, a, v, 1, "centres");
  refused(c, nan2, a, v, 1, "half_sizes");
  refused(c, h, nan1, v, 1, "angles");
  refused(c, h, a, nan2, 1, "velocities");
  refused(c, neg, a, v, 1, "half_sizes");
  refused(c, h, a, fast, 1, "speed_cap");
  refused(out, h, a, v, 1, "centres");
  refused(c, big, a, v, 1, "half sizes");
  EXPECT_NO_THROW(env.set_obstacles(0, 1, c, h, a, v));
  EXPECT_TRUE(env.collides(0, 1.0f, 1.4f));   // 0.4 m inside the 1 x 1 m square's side
  EXPECT_FALSE(env.collides(0, 1.0f, 1.8f));  // 0.3 m past it, more than body_radius 0.25
  EXPECT_THROW(env.collides(0, NAN, 0.0f), std::invalid_argument);
  EXPECT_THROW(env.set_root(0, 0.0f, INFINITY, 0.0f), std::invalid_argument);
  ObstacleTaskConfig bad = cfg;
  bad.frames_per_step = 0;
  EXPECT_THROW(ObstacleVecEnv(database(), matcher(), 1, bad), std::invalid_argument);
  bad = cfg;
  bad.obstacle_max_speed = 3.0f;
  EXPECT_THROW(ObstacleVecEnv(database(), matcher(), 1, bad), std::invalid_argument);
  EXPECT_THROW(ObstacleVecEnv(database(), matcher(), 0, cfg), std::invalid_argument);
}

}  // namespace
}  // namespace mmrl
