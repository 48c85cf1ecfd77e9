// The threaded paths against their single-threaded selves: the batched step of both tasks
// with many envs over 4 threads equals the same envs stepped on 1 thread, bit for bit (obs,
// rewards, flags, returns), and the matcher's batched search over a 4-thread pool returns what
// brute force returns for each query. In the normal build these check that threading never
// changes a result; built with -DMMRL_TSAN=ON (test tsan_threading, docs/hardening.md) they
// run under ThreadSanitizer, which reports any data race of the pool, the envs or the search.
#include <gtest/gtest.h>

#include <cstring>
#include <random>
#include <vector>

#include "env_test_database.hpp"
#include "mmrl/tasks/obstacles.hpp"
#include "mmrl/tasks/plane.hpp"
#include "mmrl/threadpool.hpp"

namespace mmrl {
namespace {

using testing_db::database;
using testing_db::matcher;

constexpr int kThreads = 4;

// Actions near valid frames' normalized trajectories (what a policy writes), plus noise.
std::vector<float> actions_for(std::mt19937& gen, int n) {
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

struct PlaneRun {
  explicit PlaneRun(int n, int threads, const TargetTaskConfig& cfg)
      : env(database(), matcher(), n, cfg, threads), obs(static_cast<size_t>(n) * PlaneVecEnv::kObsDim),
        final_obs(obs.size()), rewards(n), ret(n), terminated(n), truncated(n), success(n), len(n) {}
  void step(const std::vector<float>& a) {
    env.step(a.data(), obs.data(), rewards.data(), terminated.data(), truncated.data(), success.data(),
             final_obs.data(), ret.data(), len.data());
  }
  PlaneVecEnv env;
  std::vector<float> obs, final_obs, rewards, ret;
  std::vector<uint8_t> terminated, truncated, success;
  std::vector<int32_t> len;
};

TEST(Threading, PlaneStepOnFourThreadsEqualsOneThread) {
  const int n = 256;
  TargetTaskConfig cfg;
  cfg.max_steps = 15;  // autoresets inside the run, on every thread
  PlaneRun one(n, 1, cfg), four(n, kThreads, cfg);
  one.env.reset(5, one.obs.data());
  four.env.reset(5, four.obs.data());
  std::mt19937 gen(3);
  int ended = 0;
  for (int t = 0; t < 40; ++t) {
    const auto a = actions_for(gen, n);
    one.step(a);
    four.step(a);
    ASSERT_EQ(0, std::memcmp(one.obs.data(), four.obs.data(), sizeof(float) * one.obs.size())) << "step " << t;
    ASSERT_EQ(one.rewards, four.rewards) << "step " << t;
    ASSERT_EQ(one.terminated, four.terminated);
    ASSERT_EQ(one.truncated, four.truncated);
    for (int i = 0; i < n; ++i) {
      if (!(one.terminated[i] || one.truncated[i])) continue;
      ++ended;
      ASSERT_EQ(one.ret[i], four.ret[i]);
      ASSERT_EQ(one.len[i], four.len[i]);
      ASSERT_EQ(0, std::memcmp(&one.final_obs[i * PlaneVecEnv::kObsDim], &four.final_obs[i * PlaneVecEnv::kObsDim],
                               sizeof(float) * PlaneVecEnv::kObsDim));
    }
  }
  EXPECT_GE(ended, n);  // every env ended at least once (max_steps 15 in 40 steps)
}

struct ObstacleRun {
  explicit ObstacleRun(int n, int threads, const ObstacleTaskConfig& cfg)
      : env(database(), matcher(), n, cfg, threads), obs(static_cast<size_t>(n) * ObstacleVecEnv::kObsDim),
        final_obs(obs.size()), rewards(n), ret(n), terminated(n), truncated(n), success(n), collision(n), hits(n),
        len(n) {}
  void step(const std::vector<float>& a) {
    env.step(a.data(), obs.data(), rewards.data(), terminated.data(), truncated.data(), success.data(),
             collision.data(), hits.data(), final_obs.data(), ret.data(), len.data());
  }
  ObstacleVecEnv env;
  std::vector<float> obs, final_obs, rewards, ret;
  std::vector<uint8_t> terminated, truncated, success, collision;
  std::vector<int32_t> hits, len;
};

TEST(Threading, ObstacleStepOnFourThreadsEqualsOneThread) {
  const int n = 64;
  ObstacleTaskConfig cfg;
  cfg.num_obstacles = 30;
  cfg.max_steps = 12;
  ObstacleRun one(n, 1, cfg), four(n, kThreads, cfg);
  one.env.reset(9, one.obs.data());
  four.env.reset(9, four.obs.data());
  std::mt19937 gen(4);
  for (int t = 0; t < 25; ++t) {
    const auto a = actions_for(gen, n);
    one.step(a);
    four.step(a);
    ASSERT_EQ(0, std::memcmp(one.obs.data(), four.obs.data(), sizeof(float) * one.obs.size())) << "step " << t;
    ASSERT_EQ(one.rewards, four.rewards) << "step " << t;
    ASSERT_EQ(one.hits, four.hits);
    ASSERT_EQ(one.collision, four.collision);
    ASSERT_EQ(one.terminated, four.terminated);
    ASSERT_EQ(one.truncated, four.truncated);
  }
}

TEST(Threading, BatchedMatchOnFourThreadsEqualsBruteForce) {
  const Database& db = database();
  const Matcher& m = matcher();
  ThreadPool pool(kThreads);
  std::mt19937 gen(8);
  std::uniform_int_distribution<int64_t> frame(0, db.num_frames - 1);
  std::normal_distribution<float> noise(0.0f, 0.3f);
  const int64_t q = 2048;
  std::vector<float> queries(static_cast<size_t>(q) * kFeatureDim);
  std::vector<int64_t> bound(q), lo(q), hi(q), got(q);
  std::vector<float> cost(q);
  for (int round = 0; round < 3; ++round) {
    for (int64_t k = 0; k < q; ++k) {
      const int64_t f = frame(gen);
      for (int d = 0; d < kFeatureDim; ++d)
        queries[k * kFeatureDim + d] = db.normalized[f * kFeatureDim + d] + noise(gen);
      bound[k] = db.valid[f] ? f : -1;
      lo[k] = f;  // a window after the frame itself, as the controller excludes its clip's next frames
      hi[k] = std::min<int64_t>(f + 10, db.num_frames);
    }
    m.match_batch(queries.data(), q, got.data(), cost.data(), pool, lo.data(), hi.data(), bound.data());
    for (int64_t k = 0; k < q; ++k) {
      float want_cost = 0;
      const int64_t want = brute_force_match(db.normalized.data(), db.num_frames, kFeatureDim, db.valid.data(),
                                             &queries[k * kFeatureDim], lo[k], hi[k], bound[k], &want_cost);
      ASSERT_EQ(got[k], want) << "round " << round << " query " << k;
      ASSERT_EQ(cost[k], want_cost);
    }
  }
}

TEST(Threading, OnePoolServesManyJobsInARow) {
  // The pool's dispatch (generation counter, pending count, chunk cursor) over many short
  // jobs of every size, each element written by exactly one thread.
  ThreadPool pool(kThreads);
  std::vector<int> hits(1000);
  for (int job = 0; job < 300; ++job) {
    const int64_t n = job % 97 + 1;
    std::fill(hits.begin(), hits.end(), 0);
    pool.parallel_for(n, [&](int64_t b, int64_t e, int t) {
      ASSERT_LT(t, pool.num_threads());
      for (int64_t i = b; i < e; ++i) hits[i] += 1;
    });
    for (int64_t i = 0; i < n; ++i) ASSERT_EQ(hits[i], 1) << "job " << job;
    for (int64_t i = n; i < 1000; ++i) ASSERT_EQ(hits[i], 0);
  }
}

}  // namespace
}  // namespace mmrl
