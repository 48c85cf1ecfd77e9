// The batched target-reaching env template (vecenv.hpp) through the plane task: seeding by
// (seed, index), a continuing step against a hand computation, SAME_STEP autoreset,
// truncation, frames played against brute force, and the refused inputs.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>
#include <stdexcept>
#include <vector>

#include "env_test_database.hpp"
#include "mmrl/tasks/plane.hpp"

namespace mmrl {
namespace {

using testing_db::database;
using testing_db::matcher;

constexpr float kSentinel = -7.25f;  // rows a step must not write keep this value
constexpr int kObs = PlaneVecEnv::kObsDim;

struct PlaneBuffers {
  explicit PlaneBuffers(int n)
      : obs(static_cast<size_t>(n) * kObs), rewards(n), terminated(n), truncated(n), success(n), final_obs(), ret(), len() {
    clear_outputs(n);
  }
  void clear_outputs(int n) {
    final_obs.assign(static_cast<size_t>(n) * kObs, kSentinel);
    ret.assign(n, kSentinel);
    len.assign(n, -3);
  }
  void step(PlaneVecEnv& env, const std::vector<float>& actions) {
    clear_outputs(env.num_envs());
    env.step(actions.data(), obs.data(), rewards.data(), terminated.data(), truncated.data(), success.data(),
             final_obs.data(), ret.data(), len.data());
  }
  const float* row(int i) const { return &obs[static_cast<size_t>(i) * kObs]; }
  const float* final_row(int i) const { return &final_obs[static_cast<size_t>(i) * kObs]; }
  std::vector<float> obs, rewards;
  std::vector<uint8_t> terminated, truncated, success;
  std::vector<float> final_obs, ret;
  std::vector<int32_t> len;
};

// Policy-like actions: a random valid frame's normalized trajectory features + 0.5 noise.
std::vector<float> random_actions(std::mt19937& gen, int n) {
  const Database& db = database();
  std::vector<int64_t> valid;
  for (int64_t f = 0; f < db.num_frames; ++f)
    if (db.valid[f]) valid.push_back(f);
  std::uniform_int_distribution<size_t> pick(0, valid.size() - 1);
  std::normal_distribution<float> noise(0.0f, 0.5f);
  std::vector<float> a(static_cast<size_t>(n) * kTrajectoryDim);
  for (int i = 0; i < n; ++i) {
    const float* t = &db.normalized[static_cast<size_t>(valid[pick(gen)]) * kFeatureDim + kPoseDim];
    for (int k = 0; k < kTrajectoryDim; ++k) a[i * kTrajectoryDim + k] = t[k] + noise(gen);
  }
  return a;
}

// The root path of one step played by hand in double precision: frames j .. j+n-1 of root
// deltas (dx, dz, dyaw) in each frame's character frame (math.hpp: X_c = (c, -s), Z_c = (s, c)).
struct HandPath {
  std::vector<double> x, z, yaw;  // after each played frame
};

HandPath play_by_hand(const RootState& start, int64_t j, int frames) {
  const Database& db = database();
  HandPath p;
  double x = start.x, z = start.z, yaw = start.yaw;
  for (int k = 0; k < frames; ++k) {
    const float* d = &db.root_deltas[static_cast<size_t>(j + k) * 3];
    const double c = std::cos(yaw), s = std::sin(yaw);
    x += c * d[0] + s * d[1];
    z += -s * d[0] + c * d[1];
    yaw += d[2];
    p.x.push_back(x), p.z.push_back(z), p.yaw.push_back(yaw);
  }
  return p;
}

// Target (tx, tz) in the character frame of a root at (x, z, yaw).
void hand_goal(double tx, double tz, double x, double z, double yaw, double* gx, double* gz) {
  const double dx = tx - x, dz = tz - z, c = std::cos(yaw), s = std::sin(yaw);
  *gx = c * dx - s * dz;
  *gz = s * dx + c * dz;
}

TEST(PlaneVecEnv, SeedingByIndexGivesTheSameEnvWhateverTheBatch) {
  TargetTaskConfig cfg;
  cfg.max_steps = 12;  // truncations and resets inside the run
  PlaneVecEnv small(database(), matcher(), 3, cfg, 1), large(database(), matcher(), 5, cfg, 2);
  PlaneBuffers a(3), b(5);
  small.reset(42, a.obs.data());
  large.reset(42, b.obs.data());
  std::mt19937 gen(1);
  int ended = 0;
  for (int t = 0; t < 40; ++t) {
    for (int i = 0; i < 3; ++i) {
      const TargetEnvState &s = small.state(i), &l = large.state(i);
      ASSERT_EQ(s.frame, l.frame);
      ASSERT_EQ(s.root.x, l.root.x);
      ASSERT_EQ(s.root.z, l.root.z);
      ASSERT_EQ(s.root.yaw, l.root.yaw);
      ASSERT_EQ(s.target_x, l.target_x);
      ASSERT_EQ(s.target_z, l.target_z);
      ASSERT_EQ(0, std::memcmp(a.row(i), b.row(i), sizeof(float) * kObs)) << "step " << t << " env " << i;
    }
    std::vector<float> act = random_actions(gen, 5);
    b.step(large, act);
    act.resize(3 * kTrajectoryDim);
    a.step(small, act);
    for (int i = 0; i < 3; ++i) {
      ASSERT_EQ(a.rewards[i], b.rewards[i]);
      ASSERT_EQ(a.terminated[i], b.terminated[i]);
      ASSERT_EQ(a.truncated[i], b.truncated[i]);
      ended += a.terminated[i] || a.truncated[i];
    }
  }
  EXPECT_GE(ended, 6);  // autoresets happened, so the RNG streams were used past the first reset
  // Another seed gives other episodes.
  PlaneVecEnv other(database(), matcher(), 3, cfg, 1);
  PlaneBuffers c(3);
  other.reset(43, c.obs.data());
  small.reset(42, a.obs.data());
  EXPECT_NE(0, std::memcmp(a.obs.data(), c.obs.data(), sizeof(float) * a.obs.size()));
}

TEST(PlaneVecEnv, ContinuingStepEqualsHandComputation) {
  const Database& db = database();
  TargetTaskConfig cfg;
  const int n = 8;
  PlaneVecEnv env(db, matcher(), n, cfg, 1);
  PlaneBuffers buf(n);
  env.reset(5, buf.obs.data());
  for (int i = 0; i < n; ++i) env.set_target(i, 4.0f - i, -4.0f);  // >= 4 m away: no success within 0.2 s
  std::mt19937 gen(2);
  for (int t = 0; t < 5; ++t) {
    std::vector<TargetEnvState> before;
    for (int i = 0; i < n; ++i) before.push_back(env.state(i));
    const std::vector<float> act = random_actions(gen, n);
    buf.step(env, act);
    for (int i = 0; i < n; ++i) {
      const TargetEnvState& s0 = before[i];
      const int64_t j = decision_for_action(db, matcher(), s0.frame, &act[i * kTrajectoryDim], env.action_low(),
                                          env.action_high());
      const HandPath p = play_by_hand(s0.root, j, cfg.frames_per_step);
      const double x = p.x.back(), z = p.z.back(), yaw = p.yaw.back();
      double gx, gz;
      hand_goal(s0.target_x, s0.target_z, x, z, yaw, &gx, &gz);
      EXPECT_EQ(env.state(i).frame, j + cfg.frames_per_step);
      EXPECT_NEAR(env.state(i).root.x, x, 1e-4);
      EXPECT_NEAR(env.state(i).root.z, z, 1e-4);
      EXPECT_NEAR(buf.row(i)[kPoseDim], gx, 1e-4);
      EXPECT_NEAR(buf.row(i)[kPoseDim + 1], gz, 1e-4);
      // reward = exp(-|g|) for a step that neither succeeds nor truncates.
      // Relative tolerances: the env works in float, the hand path in double.
      const double expected = std::exp(-std::hypot(gx, gz));
      EXPECT_NEAR(buf.rewards[i], expected, 2e-4 * expected);
      const double from_obs = std::exp(-std::hypot(buf.row(i)[kPoseDim], buf.row(i)[kPoseDim + 1]));
      EXPECT_NEAR(buf.rewards[i], from_obs, 1e-5 * from_obs);
      EXPECT_EQ(buf.terminated[i], 0);
      EXPECT_EQ(buf.truncated[i], 0);
      EXPECT_EQ(buf.success[i], 0);
      EXPECT_EQ(buf.final_row(i)[0], kSentinel);  // no episode ended: final_obs untouched
      EXPECT_EQ(buf.len[i], -3);
      EXPECT_EQ(0, std::memcmp(buf.row(i), &db.normalized[static_cast<size_t>(j + cfg.frames_per_step) * kFeatureDim],
                               sizeof(float) * kPoseDim));
      EXPECT_EQ(env.state(i).steps, t + 1);
    }
    std::vector<int64_t> frames(n);
    std::vector<int32_t> played(n);
    env.current_frames(frames.data());
    env.step_frames(played.data());
    for (int i = 0; i < n; ++i) {
      EXPECT_EQ(frames[i], env.state(i).frame);
      EXPECT_EQ(played[i], cfg.frames_per_step);
    }
  }
}

TEST(PlaneVecEnv, AutoresetWritesFinalObsAndResetsFromTheEnvsOwnStream) {
  const Database& db = database();
  TargetTaskConfig cfg;
  const int n = 4;
  PlaneVecEnv env(db, matcher(), n, cfg, 2), twin(db, matcher(), n, cfg, 1);
  PlaneBuffers buf(n), tbuf(n);
  env.reset(7, buf.obs.data());
  twin.reset(7, tbuf.obs.data());
  std::vector<int32_t> played(n, -1);
  env.step_frames(played.data());
  EXPECT_EQ(played, std::vector<int32_t>(n, 0));
  // The twin's next episode of env 1 is the one env 1's autoreset must draw (a plane step
  // draws nothing from the env's RNG).
  twin.reset_env(1, tbuf.obs.data() + kObs);
  std::mt19937 gen(3);
  const std::vector<float> act = random_actions(gen, n);
  const TargetEnvState s0 = env.state(1);
  const int64_t j = decision_for_action(db, matcher(), s0.frame, &act[kTrajectoryDim], env.action_low(), env.action_high());
  const HandPath p = play_by_hand(s0.root, j, cfg.frames_per_step);
  // Put env 1's target beside the end of its path, so that the path enters the success
  // disc part-way; pick an offset whose frame distances are all clear of the radius.
  double tx = 0, tz = 0;
  int first = -1;
  for (double side : {0.30, 0.36, 0.42, 0.24}) {
    const double yaw = p.yaw.back();
    tx = p.x.back() + side * std::cos(yaw), tz = p.z.back() - side * std::sin(yaw);  // along the character's X
    first = -1;
    bool clear = true;
    for (int k = 0; k < cfg.frames_per_step; ++k) {
      const double d = std::hypot(tx - p.x[k], tz - p.z[k]);
      clear = clear && std::abs(d - cfg.success_radius) > 1e-3;
      if (first < 0 && d <= cfg.success_radius) first = k;
    }
    if (clear) break;
  }
  ASSERT_GE(first, 0);
  env.set_target(1, static_cast<float>(tx), static_cast<float>(tz));
  for (int i : {0, 2, 3}) env.set_target(i, 4.5f, 4.5f);  // out of reach this step
  buf.step(env, act);
  // Env 1 succeeded; its final observation is the end of the hand path.
  EXPECT_EQ(buf.terminated[1], 1);
  EXPECT_EQ(buf.success[1], 1);
  EXPECT_EQ(buf.truncated[1], 0);
  double gx, gz;
  hand_goal(tx, tz, p.x.back(), p.z.back(), p.yaw.back(), &gx, &gz);
  EXPECT_NEAR(buf.final_row(1)[kPoseDim], gx, 1e-4);
  EXPECT_NEAR(buf.final_row(1)[kPoseDim + 1], gz, 1e-4);
  EXPECT_EQ(0, std::memcmp(buf.final_row(1), &db.normalized[static_cast<size_t>(j + cfg.frames_per_step) * kFeatureDim],
                           sizeof(float) * kPoseDim));
  EXPECT_NEAR(buf.rewards[1], std::exp(-std::hypot(gx, gz)) + cfg.success_bonus, 1e-3);
  EXPECT_EQ(buf.ret[1], buf.rewards[1]);
  EXPECT_EQ(buf.len[1], 1);
  env.step_frames(played.data());
  EXPECT_EQ(played[1], first + 1);  // the first frame inside the disc, found by brute force above
  // ... and it was reset at once from its own stream: the twin's second episode.
  const TargetEnvState &r = env.state(1), &t = twin.state(1);
  EXPECT_EQ(r.steps, 0);
  EXPECT_EQ(r.frame, t.frame);
  EXPECT_EQ(r.root.yaw, t.root.yaw);
  EXPECT_EQ(r.target_x, t.target_x);
  EXPECT_EQ(r.target_z, t.target_z);
  EXPECT_EQ(0, std::memcmp(buf.row(1), tbuf.row(1), sizeof(float) * kObs));
  // The others continue and keep their final_obs / episode rows untouched.
  for (int i : {0, 2, 3}) {
    EXPECT_EQ(buf.terminated[i] + buf.truncated[i], 0);
    EXPECT_EQ(buf.final_row(i)[0], kSentinel);
    EXPECT_EQ(buf.ret[i], kSentinel);
    EXPECT_EQ(played[i], cfg.frames_per_step);
    EXPECT_EQ(env.state(i).steps, 1);
  }
}

TEST(PlaneVecEnv, TruncatesAtMaxSteps) {
  TargetTaskConfig cfg;
  cfg.max_steps = 3;
  const int n = 4;
  PlaneVecEnv env(database(), matcher(), n, cfg, 1);
  PlaneBuffers buf(n);
  env.reset(9, buf.obs.data());
  for (int i = 0; i < n; ++i) env.set_target(i, -4.8f, 4.8f + i);
  std::mt19937 gen(4);
  for (int t = 1; t <= 3; ++t) {
    buf.step(env, random_actions(gen, n));
    for (int i = 0; i < n; ++i) {
      EXPECT_EQ(buf.terminated[i], 0);
      EXPECT_EQ(buf.truncated[i], t == 3) << "step " << t;
      if (t == 3) {
        EXPECT_EQ(buf.len[i], 3);
        EXPECT_NE(buf.final_row(i)[0], kSentinel);
        EXPECT_EQ(env.state(i).steps, 0);
      }
    }
  }
}

TEST(PlaneVecEnv, RefusesBadInput) {
  const Database& db = database();
  TargetTaskConfig cfg;
  EXPECT_THROW(PlaneVecEnv(db, matcher(), 0, cfg), std::invalid_argument);
  cfg.frames_per_step = 31;
  EXPECT_THROW(PlaneVecEnv(db, matcher(), 1, cfg), std::invalid_argument);
  cfg.frames_per_step = 0;
  EXPECT_THROW(PlaneVecEnv(db, matcher(), 1, cfg), std::invalid_argument);
  cfg = TargetTaskConfig{};
  cfg.min_target_distance = cfg.target_half_extent;
  EXPECT_THROW(PlaneVecEnv(db, matcher(), 1, cfg), std::invalid_argument);
  cfg = TargetTaskConfig{};
  cfg.success_radius = 0;
  EXPECT_THROW(PlaneVecEnv(db, matcher(), 1, cfg), std::invalid_argument);
  const Matcher fewer(db.normalized.data(), db.num_frames - 1, kFeatureDim, db.valid.data());
  try {
    PlaneVecEnv env(db, fewer, 1, TargetTaskConfig{});
    FAIL() << "a matcher over other rows was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("matcher"), std::string::npos);
  }
  PlaneVecEnv env(db, matcher(), 1, TargetTaskConfig{});
  EXPECT_THROW(env.set_target(0, NAN, 0.0f), std::invalid_argument);
  EXPECT_THROW(env.set_target(0, 0.0f, INFINITY), std::invalid_argument);
}

}  // namespace
}  // namespace mmrl
