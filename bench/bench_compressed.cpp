// A compressed controller against the database controller it replaces, in the C++ runtime
// (docs/compressed.md): file size, memory once loaded, load time, and microseconds per character
// per frame of RuntimeCharacter::update on one thread, the two controllers in alternating rounds
// (medians: this machine is noisy), with the compressed one's split.
//
//   bench_compressed DATABASE.mmrl COMPRESSED.mmrl [CHARACTERS] [FRAMES] [ROUNDS]
//
// The split (us per character per frame, each part timed on its own over the same calls the
// runtime makes): policy (one act per 6 frames), projector (one per 6 frames), stepper (one per
// frame), decompressor (7 rows per 6 frames, decoded together: the chosen state and every frame
// shown); "playback" is
// the rest of update: the pose from the rows, inertialization, foot locking and IK.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "mmrl/compressed_source.hpp"
#include "mmrl/runtime.hpp"

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

long file_size(const std::string& path) {
  std::ifstream f(path, std::ios::binary | std::ios::ate);
  return f ? static_cast<long>(f.tellg()) : -1;
}

// Seconds per character per frame of `chars` characters walking to targets for `frames` frames.
double run_characters(const std::shared_ptr<const mmrl::RuntimeController>& c, int chars, int frames) {
  std::vector<std::unique_ptr<mmrl::RuntimeCharacter>> cs;
  const int64_t starts = c->database().num_frames;
  std::vector<int64_t> valid;
  for (int64_t f = 0; f < starts; ++f)
    if (c->database().valid[f]) valid.push_back(f);
  for (int i = 0; i < chars; ++i)
    cs.push_back(std::make_unique<mmrl::RuntimeCharacter>(c, float(i), 0.0f, 0.0f,
                                                          valid[static_cast<size_t>(i) % valid.size()]));
  const float dt = 1.0f / c->fps();
  const auto t0 = Clock::now();
  for (int k = 0; k < frames; ++k)
    for (int i = 0; i < chars; ++i) {
      if (k % 90 == 0) cs[i]->set_target(float(i) + (k / 90 % 2 ? 5.0f : -5.0f), 5.0f * float(k / 90 % 3));
      cs[i]->update(dt);
    }
  return since(t0) / (double(chars) * frames);
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

void report_file(const char* what, const std::string& path) {
  double best = 1e9;
  std::shared_ptr<const mmrl::RuntimeController> c;
  for (int k = 0; k < 3; ++k) {
    const auto t0 = Clock::now();
    c = mmrl::RuntimeController::load(path);
    best = std::min(best, since(t0));
  }
  std::printf("%-10s %s: file %.2f MB, loaded %.2f MB, load %.3f s (best of 3), %d frames kept\n", what, path.c_str(),
              file_size(path) / 1e6, c->memory_bytes() / 1e6, best, c->database().num_frames);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: bench_compressed DATABASE.mmrl COMPRESSED.mmrl [CHARACTERS] [FRAMES] [ROUNDS]\n");
    return 2;
  }
  const int chars = argc > 3 ? std::atoi(argv[3]) : 100;
  const int frames = argc > 4 ? std::atoi(argv[4]) : 300;
  const int rounds = argc > 5 ? std::atoi(argv[5]) : 5;
  try {
    report_file("database", argv[1]);
    report_file("compressed", argv[2]);
    const auto db = mmrl::RuntimeController::load(argv[1]);
    const auto lmm = mmrl::RuntimeController::load(argv[2]);
    const auto* source = dynamic_cast<const mmrl::CompressedSource*>(lmm->motion_source().get());
    if (source == nullptr) throw std::invalid_argument(std::string(argv[2]) + " is not a compressed controller");
    const mmrl::CompressedModel* m = &source->model();
    std::vector<double> a, b;
    for (int r = 0; r < rounds; ++r) {
      a.push_back(run_characters(db, chars, frames) * 1e6);
      b.push_back(run_characters(lmm, chars, frames) * 1e6);
    }
    const double ta = median(a), tb = median(b);
    std::printf("%d characters x %d frames, one thread, %d alternating rounds (medians): database %.2f us, "
                "compressed %.2f us per character per frame (%.2fx)\n", chars, frames, rounds, ta, tb, tb / ta);
    // The split, each network on its own (the same sizes and call counts as update makes).
    const int F = lmm->task().frames_per_step, n = 20000;
    mmrl::CompressedScratch scratch = m->make_scratch();
    std::vector<float> state(source->frame_states(), source->frame_states() + m->state_dim()), out(m->state_dim()),
        query(state.begin(), state.begin() + mmrl::kFeatureDim);
    std::vector<float> states, poses(static_cast<size_t>(F + 1) * m->pose_dim());
    for (int k = 0; k <= F; ++k) states.insert(states.end(), state.begin(), state.end());
    mmrl::PolicyScratch ps = lmm->policy().make_scratch();
    std::vector<float> obs(lmm->policy().obs_dim(), 0.1f), action(12);
    auto time_it = [&](auto&& f) {
      const auto t0 = Clock::now();
      for (int k = 0; k < n; ++k) f();
      return since(t0) / n * 1e6;
    };
    const double t_policy = time_it([&] { lmm->policy().act(obs.data(), action.data(), ps); }) / F;
    const double t_project = time_it([&] { m->project(query.data(), out.data(), scratch); }) / F;
    const double t_step = time_it([&] {
      std::copy(state.begin(), state.end(), out.begin());
      m->step(out.data(), scratch);
    });
    const double t_decode = time_it([&] { m->decode_rows(states.data(), poses.data(), F + 1, scratch); }) / F;
    std::printf("  compressed split (us per character per frame): policy %.2f, projector %.2f, stepper %.2f, "
                "decompressor %.2f, playback (pose, inertialization, foot locking, IK) %.2f\n", t_policy, t_project,
                t_step, t_decode, tb - t_policy - t_project - t_step - t_decode);
    std::printf("  networks: %zu parameters (%.2f MB as float32; held as float16: %.2f MB)\n", m->num_parameters(),
                4e-6 * m->num_parameters(),
                1e-6 * (m->decompressor.memory_bytes() + m->stepper.memory_bytes() + m->projector.memory_bytes()));
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_compressed: %s\n", e.what());
    return 1;
  }
  return 0;
}
