// The C++ runtime's costs (runtime.hpp): load time, memory per frame next to the .npz
// database's, and microseconds per character per frame with the split between search,
// policy, pose, IK and inertialization. One thread (the goal: 1000 characters at 30 fps on
// one core, i.e. under 33 us per character per frame, the match every 6 frames included).
//
//   bench_runtime CONTROLLER [NPZ] [CHARACTERS] [FRAMES]
//   (or $MMRL_BENCH_CONTROLLER, $MMRL_BENCH_NPZ)
//
// The split: decisions do not depend on poses, IK or inertialization (character.hpp), so every
// variant below plays the same frames; each part is the difference between two variants:
//   policy           observation + the policy's act (timed on its own)
//   search           the fast path (match + root motion) minus nothing else
//   pose             poses without IK and inertialization, minus the fast path
//   inertialization  + inertialization, minus the above
//   IK               + foot locking and leg IK (the full path), minus the above
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "mmrl/database_source.hpp"
#include "mmrl/runtime.hpp"

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

struct Variant {
  const char* name;
  bool poses, inertialization, ik;
};

// Seconds for `chars` characters of the given options to make `decisions` decisions each, the
// policy acting on the plane observation toward per-character targets.
double run_variant(const mmrl::RuntimeController& c, const Variant& v, int chars, int decisions, bool policy_only) {
  mmrl::CharacterOptions o = c.character_options();
  o.poses = v.poses;
  o.inertialization_halflife = v.inertialization ? o.inertialization_halflife : 0.0f;
  o.ik = o.foot_locking = v.ik;
  const mmrl::Database& db = c.database();
  std::vector<int64_t> valid;
  for (int64_t f = 0; f < db.num_frames; ++f)
    if (db.valid[f]) valid.push_back(f);
  std::vector<std::unique_ptr<mmrl::Character>> cs;
  mmrl::TaskConfig plain;  // the file's task options a decision reads, without its rules
  plain.action_limit_std = c.task().config->action_limit_std;
  plain.transition_cost = c.task().config->transition_cost;
  mmrl::DatabaseDecider decider(db, c.matcher(), plain);
  for (int i = 0; i < chars; ++i) {
    cs.push_back(std::make_unique<mmrl::Character>(db, o));
    mmrl::show_database_frame(*cs.back(), db, valid[(static_cast<size_t>(i) * 7919) % valid.size()],
                              mmrl::RootState{float(i), 0.0f, 0.0f});
  }
  mmrl::PolicyScratch scratch = c.policy().make_scratch();
  std::vector<float> obs(c.policy().obs_dim()), action(12);
  const auto t0 = Clock::now();
  for (int d = 0; d < decisions; ++d)
    for (int i = 0; i < chars; ++i) {
      mmrl::Character& ch = *cs[i];
      const float* pose = &db.normalized[static_cast<size_t>(ch.frame()) * mmrl::kFeatureDim];
      std::copy(pose, pose + mmrl::kPoseDim, obs.begin());
      const mmrl::Vec2 g = mmrl::world_to_local_xz(float(i) + 5.0f * ((d / 20) % 2) - ch.root().x,
                                                   5.0f - ch.root().z, ch.root().yaw);
      obs[mmrl::kPoseDim] = g.x();
      obs[mmrl::kPoseDim + 1] = g.y();
      c.policy().act(obs.data(), action.data(), scratch);
      if (policy_only) continue;
      const mmrl::Decision decision = decider.decide(ch.frame(), action.data());
      mmrl::play_database_match(ch, db, decision.match, decision.cost);
    }
  return since(t0);
}

long file_size(const std::string& path) {
  std::ifstream f(path, std::ios::binary | std::ios::ate);
  return f ? static_cast<long>(f.tellg()) : -1;
}

void report_load(const std::string& path) {
  double best = 1e9;
  mmrl::RuntimeLoadTimes t;
  std::shared_ptr<const mmrl::RuntimeController> c;
  for (int k = 0; k < 3; ++k) {
    const auto t0 = Clock::now();
    c = mmrl::RuntimeController::load(path);
    const double s = since(t0);
    if (s < best) best = s, t = c->load_times();
  }
  std::printf("load %s: %d frames, %d joints: %.3f s (best of 3; read + checksums %.3f, database %.3f, "
              "search tree %.3f, policy %.4f)\n", path.c_str(), c->database().num_frames, c->num_joints(), best,
              t.read_and_check, t.database, t.search_tree, t.policy);
}

}  // namespace

int main(int argc, char** argv) {
  const char* env_c = std::getenv("MMRL_BENCH_CONTROLLER");
  const char* env_n = std::getenv("MMRL_BENCH_NPZ");
  const std::string path = argc > 1 ? argv[1] : env_c ? env_c : "";
  const std::string npz = argc > 2 ? argv[2] : env_n ? env_n : "";
  const int chars = argc > 3 ? std::atoi(argv[3]) : 1000;
  const int frames = argc > 4 ? std::atoi(argv[4]) : 300;
  if (path.empty()) {
    std::fprintf(stderr, "usage: bench_runtime CONTROLLER [NPZ] [CHARACTERS] [FRAMES]\n");
    return 2;
  }
  try {
    report_load(path);
    const auto c = mmrl::RuntimeController::load(path);
    const double n = c->database().num_frames;
    std::printf("memory: controller %.1f MB = %.0f bytes per frame (file %.0f bytes per frame", c->memory_bytes() / 1e6,
                c->memory_bytes() / n, file_size(path) / n);
    if (!npz.empty()) std::printf("; npz database %.0f bytes per frame", file_size(npz) / n);
    std::printf(")\n");
    const int F = c->task().frames_per_step, decisions = std::max(1, frames / F);
    const double per = 1e6 / (double(chars) * decisions * F);  // seconds -> us per character per frame
    const Variant variants[] = {{"fast", false, false, false}, {"pose", true, false, false},
                                {"inert", true, true, false}, {"full", true, true, true}};
    double s[4];
    const double policy = run_variant(*c, variants[0], chars, decisions, true) * per;
    for (int k = 0; k < 4; ++k) s[k] = run_variant(*c, variants[k], chars, decisions, false) * per;
    std::printf("%d characters x %d frames, one thread: %.2f us per character per frame (%.0f characters at 30 fps "
                "per core)\n", chars, decisions * F, s[3], 1e6 / (30.0 * s[3]));
    std::printf("  split (us per character per frame): policy %.2f, search %.2f, pose %.2f, inertialization %.2f, "
                "IK %.2f\n", policy, s[0] - policy, s[1] - s[0], s[2] - s[1], s[3] - s[2]);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_runtime: %s\n", e.what());
    return 1;
  }
  return 0;
}
