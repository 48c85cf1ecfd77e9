// What the motion-quality metrics read from the C++ core:
//   - the envs' last_step_transitions (the fast-path transition flag and matched cost logged during
//     training) against decision.hpp's rule (decision_for_action) in lockstep with the same
//     actions and a hand computation of the cost, through autoresets, for both tasks;
//   - Character::animated_feet (the ankles before foot locking and IK) against a second
//     Character with IK off: one run measures foot sliding with IK on and off.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "env_test_database.hpp"
#include "mmrl/character.hpp"
#include "mmrl/database_source.hpp"
#include "mmrl/tasks/obstacles.hpp"
#include "mmrl/tasks/plane.hpp"

namespace mmrl {
namespace {

using testing_db::database;
using testing_db::matcher;

// Policy-like actions: a random valid frame's normalized trajectory features + noise (std `noise`).
std::vector<float> random_actions(std::mt19937& gen, int n, float noise_std = 0.5f) {
  const Database& db = database();
  std::vector<int64_t> valid;
  for (int64_t f = 0; f < db.num_frames; ++f)
    if (db.valid[f]) valid.push_back(f);
  std::uniform_int_distribution<size_t> pick(0, valid.size() - 1);
  std::normal_distribution<float> noise(0.0f, noise_std);
  std::vector<float> a(static_cast<size_t>(n) * kTrajectoryDim);
  for (int i = 0; i < n; ++i) {
    const float* t = &db.normalized[static_cast<size_t>(valid[pick(gen)]) * kFeatureDim + kPoseDim];
    for (int k = 0; k < kTrajectoryDim; ++k) a[i * kTrajectoryDim + k] = t[k] + noise(gen);
  }
  return a;
}

// The matched cost by hand (double): |query - normalized[match]|^2 with the query of `frame`
// and the action clipped to the env's box.
double hand_cost(int64_t frame, int64_t match, const float* action, const float* low, const float* high) {
  const Database& db = database();
  double sum = 0;
  for (int k = 0; k < kFeatureDim; ++k) {
    const double q = k < kPoseDim ? db.normalized[static_cast<size_t>(frame) * kFeatureDim + k]
                                  : std::min(high[k - kPoseDim], std::max(low[k - kPoseDim], action[k - kPoseDim]));
    const double d = q - db.normalized[static_cast<size_t>(match) * kFeatureDim + k];
    sum += d * d;
  }
  return sum;
}

struct Lockstep {
  int steps = 0, transitions = 0, ended = 0, ended_with_transition = 0;
};

// Steps `env` (through `step`) and decides for each env's state before the step by the rule;
// the env's last_step_transitions must equal that decision bit for bit.
template <class Env, class StepFn>
Lockstep run_lockstep(Env& env, int steps, StepFn&& step) {
  const int n = env.num_envs();
  std::mt19937 gen(11);
  std::vector<uint8_t> transitions(n, 7), ended(n);
  std::vector<float> costs(n, -1.0f);
  Lockstep out;
  for (int t = 0; t < steps; ++t) {
    const std::vector<float> act = random_actions(gen, n, t % 2 ? 0.5f : 2.0f);
    std::vector<TargetEnvState> before;
    for (int i = 0; i < n; ++i) before.push_back(env.state(i));
    step(act, ended);
    env.last_step_transitions(transitions.data(), costs.data());
    for (int i = 0; i < n; ++i) {
      float rule_cost = 0;
      const int64_t match = decision_for_action(database(), matcher(), before[i].frame, &act[i * kTrajectoryDim],
                                                env.action_low(), env.action_high(), &rule_cost);
      EXPECT_EQ(transitions[i], match != before[i].frame ? 1 : 0) << "step " << t << " env " << i;
      EXPECT_EQ(costs[i], rule_cost) << "step " << t << " env " << i;
      EXPECT_EQ(env.state(i).last_step.match, match);
      const double c = hand_cost(before[i].frame, match, &act[i * kTrajectoryDim], env.action_low(),
                                 env.action_high());
      EXPECT_NEAR(costs[i], c, 1e-4 * (1.0 + c));
      out.steps += 1;
      out.transitions += transitions[i];
      out.ended += ended[i];
      out.ended_with_transition += ended[i] && transitions[i];
    }
  }
  return out;
}

TEST(PlaneVecEnv, LastStepMatchesEqualACharacterInLockstepThroughAutoresets) {
  TargetTaskConfig cfg;
  cfg.max_steps = 7;           // truncations: the values must survive the autoreset
  cfg.target_half_extent = 1.5f;  // near targets: successes too
  const int n = 6;
  PlaneVecEnv env(database(), matcher(), n, cfg, 2);
  std::vector<float> obs(n * PlaneVecEnv::kObsDim), fo(obs.size()), rew(n), ret(n);
  std::vector<uint8_t> te(n), tr(n), su(n);
  std::vector<int32_t> len(n);
  env.reset(3, obs.data());
  const Lockstep r = run_lockstep(env, 30, [&](const std::vector<float>& act, std::vector<uint8_t>& ended) {
                                    env.step(act.data(), obs.data(), rew.data(), te.data(), tr.data(), su.data(),
                                             fo.data(), ret.data(), len.data());
                                    for (int i = 0; i < n; ++i) ended[i] = te[i] || tr[i];
                                  });
  EXPECT_GT(r.transitions, 10);
  EXPECT_LT(r.transitions, r.steps);  // continuations too
  EXPECT_GE(r.ended_with_transition, 2);
  // reset(seed) clears them.
  std::vector<uint8_t> transitions(n, 7);
  std::vector<float> costs(n, -1.0f);
  env.reset(4, obs.data());
  env.last_step_transitions(transitions.data(), costs.data());
  for (int i = 0; i < n; ++i) {
    EXPECT_EQ(transitions[i], 0);
    EXPECT_EQ(costs[i], 0.0f);
  }
}

TEST(ObstacleVecEnv, LastStepMatchesEqualACharacterInLockstepThroughAutoresets) {
  ObstacleTaskConfig cfg;
  cfg.num_obstacles = 40;
  cfg.obstacle_max_speed = 1.0f;  // collisions end episodes part-way through a step
  cfg.max_steps = 9;
  const int n = 6;
  ObstacleVecEnv env(database(), matcher(), n, cfg, 2);
  const int O = ObstacleVecEnv::kObsDim;
  std::vector<float> obs(n * O), fo(obs.size()), rew(n), ret(n);
  std::vector<uint8_t> te(n), tr(n), su(n), co(n);
  std::vector<int32_t> hits(n), len(n);
  env.reset(5, obs.data());
  const Lockstep r = run_lockstep(env, 30, [&](const std::vector<float>& act, std::vector<uint8_t>& ended) {
                                    env.step(act.data(), obs.data(), rew.data(), te.data(), tr.data(), su.data(),
                                             co.data(), hits.data(), fo.data(), ret.data(), len.data());
                                    for (int i = 0; i < n; ++i) ended[i] = te[i] || tr[i];
                                  });
  EXPECT_GT(r.transitions, 10);
  EXPECT_GE(r.ended_with_transition, 2);
}

TEST(Character, AnimatedFeetAreTheAnklesOfTheSameRunWithIkOff) {
  // The synthetic walkers' feet slide with the root, so the contact detector finds few
  // plants; alternating 10-frame contacts make the locks and the IK work.
  Database db = database();
  for (int64_t f = 0; f < db.num_frames; ++f)
    for (int side = 0; side < 2; ++side) db.contacts[f * 2 + side] = ((f / 10) + side) % 2 == 0;
  CharacterOptions on, off;
  off.ik = false;
  off.foot_locking = false;
  Character a(db, on), b(db, off);
  DatabaseDecider decider(db, matcher(), TaskConfig{});
  const int64_t start = db.clip_ranges[2 * 3] + 4;
  show_database_frame(a, db, start, RootState{1.0f, -2.0f, 0.4f});
  show_database_frame(b, db, start, RootState{1.0f, -2.0f, 0.4f});
  const int F = on.frames_per_step, J = db.num_joints;
  std::mt19937 gen(2);
  double moved_by_ik = 0;
  for (int t = 0; t < 40; ++t) {
    const std::vector<float> act = random_actions(gen, 1);
    const Decision d = decider.decide(a.frame(), act.data());
    play_database_match(a, db, d.match, d.cost);
    play_database_match(b, db, d.match, d.cost);
    ASSERT_EQ(a.last_match(), b.last_match());
    for (int k = 0; k < F; ++k)
      for (int side = 0; side < 2; ++side) {
        const int foot = db.roles.foot[side];
        for (int c = 0; c < 3; ++c) {
          const float anim = a.animated_feet()[(k * 2 + side) * 3 + c];
          ASSERT_EQ(anim, b.global_positions()[(static_cast<size_t>(k) * J + foot) * 3 + c])
              << "step " << t << " frame " << k << " side " << side;
          moved_by_ik = std::max<double>(moved_by_ik,
                                         std::abs(anim - a.global_positions()[(static_cast<size_t>(k) * J + foot) * 3 + c]));
        }
      }
  }
  EXPECT_GT(moved_by_ik, 1e-3);  // the locks moved the shown ankles: the two differ
  for (int c = 0; c < 6; ++c) EXPECT_EQ(a.current_animated_feet()[c], a.animated_feet()[(F - 1) * 6 + c]);
}

}  // namespace
}  // namespace mmrl
