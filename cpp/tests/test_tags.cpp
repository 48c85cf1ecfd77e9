// Tags on clips and requests (tags.hpp): parsing against hand-written answers, the request
// filter in the exact search against a brute-force scan with the same rule, the env's episode
// starts and matches inside the request, its request code, and the per-episode mix.
#include <gtest/gtest.h>

#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "env_test_database.hpp"
#include "mmrl/tags.hpp"
#include "mmrl/tasks/plane.hpp"

namespace mmrl {
namespace {

// The env test database (12 clips: speeds 0.3, 1.0, 1.6, 2.5 m/s x turns straight, left,
// right) tagged speed=slow for the first six clips, speed=fast for the rest, and turn=...
const Database& tagged() {
  static const Database db = [] {
    Database d = testing_db::database();
    d.tag_names = {"speed=fast", "speed=slow", "turn=left", "turn=right", "turn=straight"};
    const int C = d.num_clips();
    d.clip_tags.assign(static_cast<size_t>(C) * 5, 0);
    for (int c = 0; c < C; ++c) {
      d.clip_tags[c * 5 + (c < 6 ? 1 : 0)] = 1;
      d.clip_tags[c * 5 + (c % 3 == 0 ? 4 : c % 3 == 1 ? 2 : 3)] = 1;
    }
    d.validate();
    return d;
  }();
  return db;
}

const Matcher& tagged_matcher() {
  static const Matcher m(tagged().normalized.data(), tagged().num_frames, kFeatureDim, tagged().valid.data());
  return m;
}

TEST(Tags, ParseCanonicalAndSelect) {
  const Database& db = tagged();
  EXPECT_EQ(parse_request(db, "").text, "");
  EXPECT_EQ(parse_request(db, " * ").text, "");
  EXPECT_EQ(parse_request(db, " turn = left|right&speed=fast ").text, "turn=left|right & speed=fast");
  const RequestSelection s = select_request(db, "speed=fast & turn=left|right");
  ASSERT_TRUE(s.restricts());
  // Hand answer: fast clips are 6..11; left or right are c % 3 != 0.
  for (int c = 0; c < db.num_clips(); ++c) EXPECT_EQ(s.clip_mask[c], (c >= 6 && c % 3 != 0) ? 1 : 0) << c;
  std::vector<int64_t> starts, want;
  for (int64_t k = 0; k < s.num_start_frames(); ++k) starts.push_back(s.start_frame(k));
  for (int64_t f : db.valid_frames)
    if (s.clip_mask[db.frame_clip[f]]) want.push_back(f);
  EXPECT_EQ(starts, want);  // the valid frames of the allowed clips, ascending
  const RequestSelection every = select_request(db, "");
  std::vector<int64_t> all;
  for (int64_t k = 0; k < every.num_start_frames(); ++k) all.push_back(every.start_frame(k));
  EXPECT_EQ(all, db.valid_frames);
}

TEST(Tags, BadRequestsNameWhatIsWrongAndListTheTags) {
  const Database& db = tagged();
  auto message = [&](const std::string& text) {
    try {
      select_request(db, text);
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(message("style=elderly").find("no tag group 'style'"), std::string::npos);
  EXPECT_NE(message("speed=medium").find("no tag 'speed=medium'"), std::string::npos);
  EXPECT_NE(message("speed=fast & speed=slow").find("named twice"), std::string::npos);
  EXPECT_NE(message("fast").find("not group=value"), std::string::npos);
  for (const char* bad : {"style=elderly", "speed=medium", "fast"})
    EXPECT_NE(message(bad).find("speed=fast|slow; turn=left|right|straight"), std::string::npos) << message(bad);
  // A request no clip satisfies selects nothing.
  Database none = tagged();
  none.tag_names.push_back("mood=sad");
  std::vector<uint8_t> t;
  for (int c = 0; c < none.num_clips(); ++c) {
    for (int k = 0; k < 5; ++k) t.push_back(tagged().clip_tags[c * 5 + k]);
    t.push_back(0);
  }
  none.clip_tags = t;
  none.validate();
  EXPECT_THROW(select_request(none, "mood=sad"), std::invalid_argument);
  const Database& untagged = testing_db::database();
  try {
    select_request(untagged, "speed=fast");
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("has no tags"), std::string::npos) << e.what();
  }
  // Malformed tags are refused by validate().
  Database badname = tagged();
  badname.tag_names[0] = "speedfast";
  EXPECT_THROW(badname.validate(), std::invalid_argument);
  Database badsize = tagged();
  badsize.clip_tags.pop_back();
  EXPECT_THROW(badsize.validate(), std::invalid_argument);
}

TEST(Tags, RequestFilterSearchEqualsBruteForce) {
  const Database& db = tagged();
  const Matcher& m = tagged_matcher();
  std::mt19937 rng(5);
  std::normal_distribution<float> g(0.0f, 1.5f);
  for (const char* text : {"speed=fast", "turn=left", "speed=slow & turn=right|straight"}) {
    const RequestSelection s = select_request(db, text);
    RequestFilter filter;
    filter.set(db, s.clip_mask.data(), nullptr);
    for (int q = 0; q < 200; ++q) {
      float query[kFeatureDim];
      for (float& v : query) v = g(rng);
      const int64_t frame = db.valid_frames[rng() % db.valid_frames.size()];
      const int64_t c = db.frame_clip[frame];
      const int64_t lo = std::max<int64_t>(db.clip_ranges[c * 2], frame - kMatchExcludeWindow);
      const int64_t hi = std::min<int64_t>(db.clip_ranges[c * 2 + 1], frame + kMatchExcludeWindow + 1);
      const float bias = (q % 2) ? 3.0f : 0.0f;
      float tree_cost = 0, brute_cost = 0;
      const int64_t a = m.match(query, lo, hi, frame, &tree_cost, bias, &filter);
      const int64_t b = brute_force_match(db.normalized.data(), db.num_frames, kFeatureDim, db.valid.data(), query, lo,
                                          hi, frame, &brute_cost, bias, &filter);
      ASSERT_EQ(a, b) << text << " query " << q;
      EXPECT_EQ(tree_cost, brute_cost);
      // The continuation may win only if its clip is in the request (it is refused otherwise).
      ASSERT_GE(a, 0);
      EXPECT_TRUE(s.clip_mask[db.frame_clip[a]]) << text;
    }
  }
}

TEST(Tags, EnvKeepsToItsRequestAndObservesItsCode) {
  const Database& db = tagged();
  PlaneTaskConfig config;
  config.request_groups = {"speed"};
  config.transition_cost = 0.5f;
  PlaneVecEnv env(db, tagged_matcher(), 4, config, 2);
  ASSERT_EQ(env.request_dim(), 2);
  ASSERT_EQ(env.obs_dim(), PlaneVecEnv::kObsDim + 2);
  env.set_request(1, "speed=fast & turn=left");
  env.set_request(2, "turn=right");  // a group the policy is not conditioned on: filtered, code all 0
  EXPECT_THROW(env.set_request(3, "speed=warp"), std::invalid_argument);
  EXPECT_EQ(env.request(3).request.text, "");  // unchanged by the refused request
  const int N = 4, D = env.obs_dim();
  std::vector<float> obs(N * D), rew(N), fin(N * D), ret(N);
  std::vector<uint8_t> term(N), trunc(N), succ(N);
  std::vector<int32_t> len(N);
  env.reset(3, obs.data());
  std::mt19937 rng(9);
  std::normal_distribution<float> g(0.0f, 1.0f);
  std::vector<float> actions(N * kTrajectoryDim);
  int sampled_fast = 0, sampled_slow = 0, sampled_free = 0;
  for (int step = 0; step < 400; ++step) {
    for (int i = 0; i < N; ++i) {
      const RequestSelection& r = env.request(i);
      const int clip = db.frame_clip[env.state(i).frame];
      if (r.restricts()) EXPECT_TRUE(r.clip_mask[clip]) << "env " << i << " step " << step << " " << r.request.text;
      // The code: speed=fast -> (1, 0), speed=slow -> (0, 1) (tag order fast, slow); free -> (0, 0).
      const float* code = &obs[i * D + PlaneVecEnv::kObsDim];
      const std::string& t = r.request.text;
      const bool fast = t.find("speed=fast") != std::string::npos, slow = t.find("speed=slow") != std::string::npos;
      EXPECT_EQ(code[0], fast ? 1.0f : 0.0f) << t;
      EXPECT_EQ(code[1], slow ? 1.0f : 0.0f) << t;
      if (i == 1) EXPECT_EQ(t, "speed=fast & turn=left");
      if (i == 2) EXPECT_EQ(t, "turn=right");
      if (i == 0 || i == 3) {
        EXPECT_TRUE(t.empty() || t == "speed=fast" || t == "speed=slow") << t;
      }
    }
    for (float& a : actions) a = g(rng);
    env.step(actions.data(), obs.data(), rew.data(), term.data(), trunc.data(), succ.data(), fin.data(), ret.data(),
             len.data());
    for (int i : {0, 3}) {
      if (term[i] || trunc[i] || step == 0) {
        const std::string& t = env.request(i).request.text;
        sampled_fast += t == "speed=fast";
        sampled_slow += t == "speed=slow";
        sampled_free += t.empty();
      }
    }
  }
  EXPECT_GT(sampled_fast, 0);
  EXPECT_GT(sampled_slow, 0);
  // Unpinning gives env 1 back to the mix.
  env.set_request(1, "");
  EXPECT_FALSE(env.request_pinned(1));
}

TEST(Tags, MixWeightsFollowTheAnyProbability) {
  const Database& db = tagged();
  const RequestCode code(db, {"speed", "turn"});
  EXPECT_EQ(code.dim(), 5);
  const RequestMix mix = request_mix(db, code, 0.25f);
  ASSERT_EQ(mix.selections.size(), 12u);  // (free + 2) x (free + 3): every combination selects frames
  double p_free_free = 0, p_fast_left = 0;
  for (size_t k = 0; k < mix.selections.size(); ++k) {
    const double p = mix.cumulative[k] - (k ? mix.cumulative[k - 1] : 0.0);
    if (mix.selections[k].request.text.empty()) p_free_free = p;
    if (mix.selections[k].request.text == "speed=fast & turn=left") p_fast_left = p;
  }
  EXPECT_NEAR(p_free_free, 0.25 * 0.25, 1e-6);
  EXPECT_NEAR(p_fast_left, (0.75 / 2) * (0.75 / 3), 1e-6);
  EXPECT_THROW(request_mix(db, code, 1.5f), std::invalid_argument);
  EXPECT_THROW(RequestCode(db, {"style"}), std::invalid_argument);
}

}  // namespace
}  // namespace mmrl
