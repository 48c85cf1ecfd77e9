// A rule that changes which frame plays, added by registration alone (rules.hpp): a toy rule
// registered by this test (a cost on candidates by one of their pose features: the left foot's
// forward position, normalized, away from the database's mean) is honoured by the batched env's decisions (against a brute-force scan with
// the rule as its filter), by the runtime's per-character decision context (runtime_task.hpp,
// what the C interface drives), and by a compressed controller's decisions (its candidates are
// states without rows, priced through the same method).
#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <random>
#include <vector>

#include "compressed_test_model.hpp"
#include "env_test_database.hpp"
#include "mmrl/compressed.hpp"
#include "mmrl/compressed_source.hpp"
#include "mmrl/rules.hpp"
#include "mmrl/runtime_task.hpp"
#include "mmrl/tasks/plane.hpp"

namespace mmrl {
namespace {

using testing_db::database;
using testing_db::matcher;

float g_weight = 0.0f;
constexpr float kWeight = 3.0f;

// The toy rule: weight * (the candidate's normalized pose feature 2)^2, read from the
// candidate's own features (a row's or a state's alike).
class FootRule final : public CandidateRule {
 public:
  explicit FootRule(float weight) : weight_(weight) {}

 protected:
  float cost(const Candidate& c) const override { return weight_ * c.features[2] * c.features[2]; }

 private:
  float weight_;
};

// Registers the toy rule for the test's scope (on when g_weight > 0).
struct ToyRuleRegistered {
  int before = static_cast<int>(candidate_rule_types().size());
  ToyRuleRegistered() {
    register_candidate_rule({"toy-foot", [](const RuleSetup&) -> std::unique_ptr<CandidateRule> {
                               if (!(g_weight > 0)) return nullptr;
                               return std::make_unique<FootRule>(g_weight);
                             }});
  }
  ~ToyRuleRegistered() { unregister_candidate_rules_after(before); }
};

// The decision of a database character on `frame` for `action` (clipped to the box) by a
// brute-force scan with `filter`: the reference.
int64_t reference(const Database& db, const float* low, const float* high, int64_t frame, const float* action,
                  const CandidateFilter* filter, float* cost) {
  float q[kFeatureDim];
  for (int k = 0; k < kPoseDim; ++k) q[k] = db.normalized[static_cast<size_t>(frame) * kFeatureDim + k];
  for (int k = 0; k < kTrajectoryDim; ++k) q[kPoseDim + k] = std::min(high[k], std::max(low[k], action[k]));
  const int c = db.frame_clip[frame];
  const int64_t lo = std::max<int64_t>(db.clip_ranges[c * 2], frame - kMatchExcludeWindow);
  const int64_t hi = std::min<int64_t>(db.clip_ranges[c * 2 + 1], frame + kMatchExcludeWindow + 1);
  return brute_force_match(db.normalized.data(), db.num_frames, kFeatureDim, db.valid.data(), q, lo, hi,
                           db.valid[frame] ? frame : -1, cost, 0.0f, filter);
}

TEST(CandidateRules, AnEnvDecidesUnderARegisteredRuleAsABruteForceScanWithIt) {
  const Database& db = database();
  ToyRuleRegistered registered;
  g_weight = kWeight;
  PlaneVecEnv env(db, matcher(), 4, PlaneTaskConfig{}, 2);
  g_weight = 0.0f;
  PlaneVecEnv plain(db, matcher(), 4, PlaneTaskConfig{}, 2);
  FootRule rule(kWeight);
  std::vector<float> obs(4 * env.obs_dim());
  env.reset(3, obs.data());
  std::mt19937 rng(5);
  std::normal_distribution<float> n(0.0f, 1.0f);
  std::uniform_int_distribution<size_t> pick(0, db.valid_frames.size() - 1);
  int changed = 0, decisions = 0;
  for (int d = 0; d < 150; ++d) {
    for (int i = 0; i < 4; ++i) {
      const int64_t frame = db.valid_frames[pick(rng)];
      env.set_state(i, frame, 0.0f, 0.0f, 0.0f);
      plain.set_state(i, frame, 0.0f, 0.0f, 0.0f);
      float action[kTrajectoryDim];
      for (float& a : action) a = n(rng);
      env.decide(i, action);
      plain.decide(i, action);
      float want_cost = 0, plain_cost = 0;
      const int64_t want = reference(db, env.action_low(), env.action_high(), frame, action, &rule, &want_cost);
      ASSERT_EQ(env.state(i).decision.match, want) << d;
      ASSERT_FLOAT_EQ(env.state(i).decision.cost, want_cost) << d;
      ASSERT_EQ(plain.state(i).decision.match, reference(db, env.action_low(), env.action_high(), frame, action,
                                                         nullptr, &plain_cost));
      changed += env.state(i).decision.match != plain.state(i).decision.match;
      ++decisions;
    }
  }
  // Not vacuous: the rule moved a good share of the decisions.
  EXPECT_GT(changed, decisions / 10) << changed << " of " << decisions;
}

TEST(CandidateRules, TheRuntimesDecisionContextHonoursARegisteredRule) {
  const Database& db = database();
  ToyRuleRegistered registered;
  g_weight = kWeight;
  RuntimeTask task;
  task.name = task.core = "plane";
  task.config = std::make_shared<PlaneTaskConfig>();
  CharacterTaskOf<PlaneTask> runtime(db, matcher(), task);  // what a RuntimeCharacter decides with
  g_weight = 0.0f;
  FootRule rule(kWeight);
  PlaneVecEnv box(db, matcher(), 1, PlaneTaskConfig{}, 1);
  std::mt19937 rng(8);
  std::normal_distribution<float> n(0.0f, 1.0f);
  std::uniform_int_distribution<size_t> pick(0, db.valid_frames.size() - 1);
  int changed = 0;
  for (int d = 0; d < 100; ++d) {
    const int64_t frame = db.valid_frames[pick(rng)];
    runtime.start(frame, 0.3f);
    runtime.sync(RootState{1.0f, 2.0f, 0.3f}, frame, 4.0f, 5.0f, RuntimeObstacles{}, d);
    float action[kTrajectoryDim];
    for (float& a : action) a = n(rng);
    runtime.decide(action);
    float want_cost = 0, plain_cost = 0;
    ASSERT_EQ(runtime.decision().match, reference(db, box.action_low(), box.action_high(), frame, action, &rule,
                                                  &want_cost)) << d;
    changed += runtime.decision().match !=
               reference(db, box.action_low(), box.action_high(), frame, action, nullptr, &plain_cost);
  }
  EXPECT_GT(changed, 10);
}

TEST(CandidateRules, ACompressedControllersStatesArePricedByARegisteredRule) {
  const Database& db = database();
  ToyRuleRegistered registered;
  const CompressedModel m = testing_db::random_model(3);  // its states' features are priced by the rule
  const int S = m.state_dim();
  std::vector<float> states(static_cast<size_t>(db.num_frames) * S, 0.0f);
  for (int64_t f = 0; f < db.num_frames; ++f)
    for (int k = 0; k < kFeatureDim; ++k) states[f * S + k] = db.normalized[f * kFeatureDim + k];
  g_weight = kWeight;
  PlaneVecEnv env(db, matcher(), 1, PlaneTaskConfig{}, 1);
  g_weight = 0.0f;
  env.set_source(std::make_shared<CompressedSource>(db, m, states.data()));
  FootRule rule(kWeight);
  std::vector<float> obs(env.obs_dim());
  env.reset(2, obs.data());
  std::mt19937 rng(4);
  std::normal_distribution<float> n(0.0f, 1.0f);
  int priced = 0;
  for (int d = 0; d < 200; ++d) {
    float action[kTrajectoryDim];
    for (float& a : action) a = n(rng);
    const std::vector<float> shown = CompressedState::of(env.motion(0)).shown;
    env.decide(0, action);
    const Decision& dec = env.state(0).decision;
    const std::vector<float>& chosen = CompressedState::of(env.motion(0)).chosen;
    float q[kFeatureDim];
    for (int k = 0; k < kPoseDim; ++k) q[k] = shown[k];
    for (int k = 0; k < kTrajectoryDim; ++k)
      q[kPoseDim + k] = std::min(env.action_high()[k], std::max(env.action_low()[k], action[k]));
    float dist = 0;
    for (int k = 0; k < kFeatureDim; ++k) dist += (q[k] - chosen[k]) * (q[k] - chosen[k]);
    const float extra = rule.extra_cost(Candidate{-1, chosen.data()});
    // The decision's cost is the chosen state's distance plus the rule's price of that state.
    ASSERT_NEAR(dec.cost, dist + extra, 1e-3f * (1.0f + dist + extra)) << d;
    priced += extra > 1e-3f;
    env.end_playback(0);
  }
  EXPECT_GT(priced, 20);
}

}  // namespace
}  // namespace mmrl
