// Compressed controllers (compressed.hpp): the network against a plain loop, the decision rule,
// playback against stepping and decoding by hand, and no allocation while a plane env and a
// character play one (counted by a replaced global operator new).
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <memory>
#include <new>
#include <random>
#include <vector>

#include "compressed_test_model.hpp"
#include "env_test_database.hpp"
#include "mmrl/character.hpp"
#include "mmrl/compressed.hpp"
#include "mmrl/compressed_source.hpp"
#include "mmrl/tasks/plane.hpp"

namespace {
std::atomic<long> g_allocations{0};
std::atomic<bool> g_counting{false};
}  // namespace

void* operator new(std::size_t n) {
  if (g_counting.load(std::memory_order_relaxed)) g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }

namespace mmrl {
namespace {

using testing_db::database;
using testing_db::matcher;

using testing_db::random_mlp;
using testing_db::random_model;

// The float16 rounding of a weight (the reference of pack()): the nearest of every finite
// half, found by search over their values (ascending with their bits), ties to the even bits.
double half_rounded(float w) {
  static const std::vector<float> halves = [] {
    std::vector<float> v;
    for (uint32_t h = 0; h < 0x7c00u; ++h) v.push_back(float16_to_float(static_cast<uint16_t>(h)));
    return v;
  }();
  const float a = std::abs(w);
  const size_t hi = std::lower_bound(halves.begin(), halves.end(), a) - halves.begin();
  size_t best = std::min(hi, halves.size() - 1);
  if (hi > 0) {
    const double below = a - halves[hi - 1], above = hi < halves.size() ? halves[hi] - a : 1e30;
    if (below < above || (below == above && (hi - 1) % 2 == 0)) best = hi - 1;
  }
  return w < 0 ? -static_cast<double>(halves[best]) : static_cast<double>(halves[best]);
}

TEST(Compressed, Float16BitsWidenToTheirValues) {
  EXPECT_EQ(float16_to_float(0x3c00u), 1.0f);
  EXPECT_EQ(float16_to_float(0xc000u), -2.0f);
  EXPECT_EQ(float16_to_float(0x7bffu), 65504.0f);
  EXPECT_EQ(float16_to_float(0x0001u), std::ldexp(1.0f, -24));
  EXPECT_EQ(float16_to_float(0x03ffu), std::ldexp(1023.0f, -24));
  EXPECT_EQ(float16_to_float(0x0400u), std::ldexp(1.0f, -14));
  EXPECT_TRUE(std::signbit(float16_to_float(0x8000u)) && float16_to_float(0x8000u) == 0.0f);
  EXPECT_TRUE(std::isinf(float16_to_float(0x7c00u)) && std::isnan(float16_to_float(0x7e00u)));
}

TEST(Compressed, MlpEqualsAPlainLoopOverItsFloat16Weights) {
  std::mt19937 rng(1);
  const Mlp plain = random_mlp(rng, {7, 45, 5, 3}, 1.0f);  // 45: blocks of eight and a remainder
  Mlp m = plain;
  m.pack();
  EXPECT_TRUE(m.layers[0].weight.empty());  // the float32 copy is released
  EXPECT_EQ(m.memory_bytes(), sizeof(uint16_t) * 8 * (6 * 7 + 1 * 45 + 1 * 5) + sizeof(float) * (45 + 5 + 3));
  std::vector<float> in{0.3f, -1.2f, 0.5f, 2.0f, -0.1f, 0.0f, 1.1f}, out(3), scratch(2 * kMlpMaxRows * m.max_width());
  m.forward(in.data(), out.data(), scratch.data());
  std::vector<double> x(in.begin(), in.end());
  for (size_t k = 0; k < plain.layers.size(); ++k) {
    const auto& l = plain.layers[k];
    std::vector<double> y(l.out);
    for (int o = 0; o < l.out; ++o) {
      double s = l.bias[o];
      for (int i = 0; i < l.in; ++i) s += half_rounded(l.weight[o * l.in + i]) * x[i];
      y[o] = k + 1 < plain.layers.size() ? (s > 0 ? s : std::expm1(s)) : s;
    }
    x = y;
  }
  for (int o = 0; o < 3; ++o) EXPECT_NEAR(out[o], x[o], 1e-5);
  m.check("net");  // a packed network checks too
  Mlp bad = m;
  bad.layers[1].in = 10;
  EXPECT_THROW(bad.check("net"), std::invalid_argument);
  Mlp huge = plain;
  huge.layers[0].weight[3] = 7e4f;
  EXPECT_THROW(huge.pack(), std::invalid_argument);
}

TEST(Compressed, PackRoundsEveryWeightToTheNearestFloat16) {
  // One layer of 1 input: out[o] = half(w[o]) * 1 + 0, over normal, subnormal and tie values.
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> e(-30.0f, 15.0f);  // |w| < 2^15 x 2, inside float16's range
  Mlp m;
  Mlp::Layer l;
  l.in = 1;
  l.out = 4000;
  for (int o = 0; o < l.out; ++o) {
    float w = std::ldexp(1.0f + std::uniform_real_distribution<float>(0, 1)(rng), static_cast<int>(e(rng)));
    if (o % 7 == 0) w = std::ldexp(1.0f + (2 * (o % 1024) + 1) / 2048.0f, -3);  // halfway between two halves
    if (o % 11 == 0) w = std::ldexp(static_cast<float>(o % 1024) + 0.5f, -24);  // halfway between subnormals
    l.weight.push_back(o % 2 ? -w : w);
  }
  l.bias.assign(l.out, 0.0f);
  m.layers.push_back(l);
  const std::vector<float> weights = l.weight;
  m.pack();
  std::vector<float> out(l.out), scratch(2 * kMlpMaxRows * m.max_width());
  const float one = 1.0f;
  m.forward(&one, out.data(), scratch.data());
  for (int o = 0; o < l.out; ++o) ASSERT_EQ(out[o], half_rounded(weights[o])) << o << " " << weights[o];
}

TEST(Compressed, EluIsExpm1BelowZero) {
  // Two identity layers: out = ELU(x), against std::expm1 over [-100, 10].
  Mlp m;
  for (int k = 0; k < 2; ++k) {
    Mlp::Layer l;
    l.in = l.out = 1;
    l.weight = {1.0f};
    l.bias = {0.0f};
    m.layers.push_back(l);
  }
  m.pack();
  std::vector<float> scratch(2 * kMlpMaxRows * m.max_width());
  double worst = 0;
  for (int k = 0; k <= 110000; ++k) {
    const float x = -100.0f + 0.001f * static_cast<float>(k);
    float y;
    m.forward(&x, &y, scratch.data());
    const double want = x > 0 ? x : std::expm1(static_cast<double>(x));
    worst = std::max(worst, std::abs(y - want) / std::max(1e-30, std::abs(want)));
  }
  EXPECT_LT(worst, 5e-7);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  float y = 0;
  m.forward(&nan, &y, scratch.data());
  EXPECT_TRUE(std::isnan(y));
}

TEST(Compressed, DecisionKeepsTheContinuationUnlessTheProjectionIsCloserByTheCost) {
  const CompressedModel m = random_model(2);
  CompressedScratch s = m.make_scratch();
  std::mt19937 rng(3);
  std::normal_distribution<float> n(0.0f, 1.0f);
  int transitions = 0, stays = 0;
  for (int trial = 0; trial < 200; ++trial) {
    std::vector<float> current(m.state_dim()), query(kFeatureDim), projected(m.state_dim()), reference(m.state_dim());
    for (float& v : current) v = n(rng);
    for (float& v : query) v = n(rng);
    const float cost_m = trial % 2 ? 0.0f : 2.0f;
    float cost = -1;
    const bool t = compressed_decision(m, current.data(), query.data(), cost_m, projected.data(), &cost, s);
    m.project(query.data(), reference.data(), s);
    for (int k = 0; k < m.state_dim(); ++k) ASSERT_EQ(projected[k], reference[k]);
    double stay = 0, jump = 0;
    for (int k = 0; k < kFeatureDim; ++k) {
      stay += (query[k] - current[k]) * (query[k] - current[k]);
      jump += (query[k] - projected[k]) * (query[k] - projected[k]);
    }
    if (std::abs(stay - jump - cost_m) > 1e-3) EXPECT_EQ(t, jump + cost_m < stay);
    EXPECT_NEAR(cost, t ? jump : stay, 1e-3);
    (t ? transitions : stays) += 1;
  }
  EXPECT_GT(transitions, 10);
  EXPECT_GT(stays, 10);
}

// A filter that prices states only: refuses a state whose first feature is above `limit`,
// and adds `extra` to the others.
class StateLimit final : public CandidateFilter {
 public:
  StateLimit(float limit, float extra) : limit_(limit), extra_(extra) {}
  float extra_cost(const Candidate& c) const override {
    return c.features[0] > limit_ ? std::numeric_limits<float>::infinity() : extra_;
  }

 private:
  float limit_, extra_;
};

TEST(Compressed, AFilteredDecisionIsTheCheapestProjectionOrTheContinuation) {
  const CompressedModel m = random_model(6);
  CompressedScratch s = m.make_scratch();
  const int S = m.state_dim();
  std::mt19937 rng(7);
  std::normal_distribution<float> n(0.0f, 1.0f);
  int refused_all = 0, filtered = 0, transitions = 0;
  for (int trial = 0; trial < 300; ++trial) {
    const int rows = 1 + trial % 7;
    std::vector<float> current(S), queries(rows * kFeatureDim), chosen(S), plain(S), proj(rows * S);
    for (float& v : current) v = n(rng);
    for (float& v : queries) v = n(rng);
    for (int r = 0; r < rows; ++r) m.project(&queries[r * kFeatureDim], &proj[r * S], s);
    const float limit = trial % 5 == 0 ? -1e30f : 0.3f * n(rng), extra = trial % 3 ? 0.5f : 0.0f, tc = trial % 2;
    const StateLimit filter(limit, extra);
    float cost = 0;
    const bool t = compressed_decision(m, current.data(), queries.data(), rows, tc, &filter, chosen.data(), &cost, s);
    // Brute force: the continuation and every projection, priced; all refused: no filter.
    auto price = [&](const float* state, bool with) {
      const double d = feature_distance(queries.data(), state);
      if (!with) return d;
      return state[0] > limit ? std::numeric_limits<double>::infinity() : d + extra;
    };
    bool with = std::isfinite(price(current.data(), true));
    for (int r = 0; r < rows; ++r) with = with || std::isfinite(price(&proj[r * S], true));
    refused_all += !with;
    filtered += with && limit > -1e29f;
    double best = std::numeric_limits<double>::infinity();
    int arg = 0;
    for (int r = 0; r < rows; ++r)
      if (price(&proj[r * S], with) < best) best = price(&proj[r * S], with), arg = r;
    const double stay = price(current.data(), with);
    if (std::abs(best + tc - stay) < 1e-3) continue;  // float rounding may decide
    const bool want = best + tc < stay;
    ASSERT_EQ(t, want) << trial;
    transitions += t;
    if (t)
      for (int k = 0; k < S; ++k) ASSERT_EQ(chosen[k], proj[arg * S + k]) << trial;
    EXPECT_NEAR(cost, want ? best : stay, 1e-3);
  }
  EXPECT_GT(refused_all, 20);
  EXPECT_GT(filtered, 100);
  EXPECT_GT(transitions, 30);
  // One query and no filter: the unfiltered rule, bit for bit.
  std::vector<float> current(S, 0.1f), query(kFeatureDim, 0.2f), a(S), b(S);
  float ca = 0, cb = 0;
  const bool ta = compressed_decision(m, current.data(), query.data(), 1.0f, a.data(), &ca, s);
  const bool tb = compressed_decision(m, current.data(), query.data(), 1, 1.0f, nullptr, b.data(), &cb, s);
  EXPECT_EQ(ta, tb);
  EXPECT_EQ(ca, cb);
  for (int k = 0; k < S; ++k) EXPECT_EQ(a[k], b[k]);
}

TEST(Compressed, PlaybackStepsAndDecodesTheChosenState) {
  const CompressedModel m = random_model(4);
  CompressedScratch s = m.make_scratch();
  std::vector<float> start(m.state_dim(), 0.2f), end(m.state_dim()), rows(7 * m.pose_dim());
  compressed_playback(m, start.data(), 6, rows.data(), end.data(), s);
  std::vector<float> state = start, pose(m.pose_dim());
  CompressedScratch s2 = m.make_scratch();
  for (int k = 0; k <= 6; ++k) {
    m.decode(state.data(), pose.data(), s2);
    for (int c = 0; c < m.pose_dim(); ++c) ASSERT_EQ(rows[k * m.pose_dim() + c], pose[c]) << k << " " << c;
    if (k < 6) m.step(state.data(), s2);
  }
  for (int c = 0; c < m.state_dim(); ++c) EXPECT_EQ(end[c], state[c]);
}

TEST(Compressed, RotationFrom6dIsTheMatrixsQuaternion) {
  const Quat q = Quat(Eigen::AngleAxisf(0.7f, Vec3(0.3f, -0.5f, 0.8f).normalized()));
  const Mat3 r = q.toRotationMatrix();
  const float six[6] = {r(0, 0), r(0, 1), r(1, 0), r(1, 1), r(2, 0), r(2, 1)};
  EXPECT_NEAR(std::abs(rotation_from_6d(six).dot(q)), 1.0f, 1e-6f);
}

TEST(Compressed, AnEnvAndACharacterPlayItWithoutAllocating) {
  const Database& db = database();
  const CompressedModel m = random_model(5);
  std::vector<float> states(static_cast<size_t>(db.num_frames) * m.state_dim());
  for (int64_t f = 0; f < db.num_frames; ++f)
    for (int k = 0; k < m.state_dim(); ++k)
      states[f * m.state_dim() + k] = k < kFeatureDim ? db.normalized[f * kFeatureDim + k] : 0.0f;
  PlaneTaskConfig config;
  PlaneVecEnv env(db, matcher(), 1, config, 1);
  env.set_source(std::make_shared<CompressedSource>(db, m, states.data()));
  std::vector<float> obs(env.obs_dim());
  env.reset(7, obs.data());
  CharacterOptions o;
  Character ch(db, o);
  std::vector<float> row(m.pose_dim());
  CompressedScratch s = m.make_scratch();
  m.decode(CompressedState::of(env.motion(0)).shown.data(), row.data(), s);
  show_compressed_row(ch, row.data(), RootState{});
  float action[kTrajectoryDim];
  std::mt19937 rng(9);
  std::normal_distribution<float> n(0.0f, 1.0f);
  int transitions = 0;
  g_allocations = 0;
  g_counting = true;
  {
    std::vector<int> probe(3);  // the counter counts
    EXPECT_EQ(g_allocations.load(), 1);
  }
  g_allocations = 0;
  for (int d = 0; d < 300; ++d) {
    for (float& a : action) a = n(rng);
    env.set_state(0, -1, ch.root().x, ch.root().z, ch.root().yaw);
    env.decide(0, action);
    play_compressed_rows(ch, CompressedState::of(env.motion(0)).rows.data(), env.state(0).decision.transition,
                         env.state(0).decision.cost);
    env.end_playback(0);
    transitions += env.state(0).decision.transition;
  }
  g_counting = false;
  EXPECT_EQ(g_allocations.load(), 0);
  EXPECT_GT(transitions, 0);
  EXPECT_EQ(ch.frame(), -1);
  for (int k = 0; k < 3 * ch.num_joints(); ++k) ASSERT_TRUE(std::isfinite(ch.current_global_positions()[k]));
  // A model of another skeleton is refused.
  CompressedModel other = m;
  other.num_joints += 1;
  CompressedModel unpacked = m;  // a model whose stepper was never packed
  std::mt19937 rng9(9);
  unpacked.stepper = random_mlp(rng9, {m.state_dim(), 16, m.state_dim()}, 0.02f);
  unpacked.check();
  EXPECT_FALSE(unpacked.prepared());
  EXPECT_THROW(env.set_source(std::make_shared<CompressedSource>(db, unpacked, states.data())), std::invalid_argument);
  EXPECT_THROW(env.set_source(std::make_shared<CompressedSource>(db, other, states.data())), std::invalid_argument);
}

}  // namespace
}  // namespace mmrl
