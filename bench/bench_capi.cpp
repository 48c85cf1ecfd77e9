// The C interface's overhead (cpp/capi/mmrl_runtime.h) over direct C++ calls (runtime.hpp):
// microseconds per character per frame, the same characters, targets and frames through both,
// in the same run, alternating rounds so the machine's noise falls on both alike. The goal
// (issue 28): at most 5% overhead.
//
//   bench_capi CONTROLLER [CHARACTERS] [FRAMES] [ROUNDS]     (or $MMRL_BENCH_CONTROLLER)
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>
#include <vector>

#include "mmrl/runtime.hpp"
#include "mmrl_runtime.h"

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

double run_cpp(const std::shared_ptr<const mmrl::RuntimeController>& c, int n, int frames) {
  std::vector<std::unique_ptr<mmrl::RuntimeCharacter>> chars;
  for (int i = 0; i < n; ++i) {
    chars.push_back(std::make_unique<mmrl::RuntimeCharacter>(c, 2.0f * i, 0.0f, 0.0f));
    chars.back()->set_target(2.0f * i + 3.0f, 4.0f);
  }
  const float dt = 1.0f / c->fps();
  std::vector<float> rot(static_cast<size_t>(c->num_joints()) * 4), tr(static_cast<size_t>(c->num_joints()) * 3);
  float root[3];
  const auto t0 = Clock::now();
  for (int f = 0; f < frames; ++f)
    for (auto& ch : chars) {
      const mmrl::RuntimePose& p = ch->update(dt);  // and the same copies the C interface makes
      std::copy(p.local_rotations, p.local_rotations + rot.size(), rot.data());
      std::copy(p.local_translations, p.local_translations + tr.size(), tr.data());
      root[0] = p.root.x, root[1] = p.root.z, root[2] = p.root.yaw;
    }
  const double s = since(t0);
  if (!(root[0] == root[0])) std::puts("");  // keep the copies
  return 1e6 * s / (static_cast<double>(n) * frames);
}

double run_c(mmrl_controller* c, int n, int frames) {
  std::vector<mmrl_character*> chars(static_cast<size_t>(n));
  for (int i = 0; i < n; ++i) {
    if (mmrl_character_create(c, 2.0f * i, 0.0f, 0.0f, -1, &chars[i]) != MMRL_OK) std::abort();
    mmrl_character_set_target(chars[i], 2.0f * i + 3.0f, 4.0f);
  }
  float fps = 30;
  int32_t J = 0;
  mmrl_controller_fps(c, &fps);
  mmrl_controller_num_joints(c, &J);
  std::vector<float> rot(static_cast<size_t>(J) * 4), tr(static_cast<size_t>(J) * 3);
  float root[3];
  const auto t0 = Clock::now();
  for (int f = 0; f < frames; ++f)
    for (mmrl_character* ch : chars)
      if (mmrl_character_update(ch, 1.0f / fps, rot.data(), tr.data(), J, root) != MMRL_OK) std::abort();
  const double s = since(t0);
  for (mmrl_character* ch : chars) mmrl_character_destroy(ch);
  return 1e6 * s / (static_cast<double>(n) * frames);
}

}  // namespace

int main(int argc, char** argv) {
  const char* env = std::getenv("MMRL_BENCH_CONTROLLER");
  const std::string path = argc > 1 ? argv[1] : (env ? env : "");
  if (path.empty()) {
    std::fprintf(stderr, "usage: bench_capi CONTROLLER [CHARACTERS] [FRAMES] [ROUNDS]\n");
    return 2;
  }
  const int n = argc > 2 ? std::atoi(argv[2]) : 200, frames = argc > 3 ? std::atoi(argv[3]) : 300,
            rounds = argc > 4 ? std::atoi(argv[4]) : 5;
  const auto cpp = mmrl::RuntimeController::load(path);
  mmrl_controller* c = nullptr;
  if (mmrl_controller_load(path.c_str(), &c) != MMRL_OK) {
    std::fprintf(stderr, "bench_capi: %s\n", mmrl_last_error());
    return 2;
  }
  std::vector<double> a, b;
  for (int r = 0; r < rounds; ++r) {  // alternate, and take each side's median
    a.push_back(run_cpp(cpp, n, frames));
    b.push_back(run_c(c, n, frames));
  }
  std::sort(a.begin(), a.end());
  std::sort(b.begin(), b.end());
  const double ma = a[a.size() / 2], mb = b[b.size() / 2];
  std::printf("%d characters x %d frames, %d rounds (medians): C++ %.2f us, C interface %.2f us per character per "
              "frame: %+.1f%% (goal <= +5%%)\n", n, frames, rounds, ma, mb, 100.0 * (mb / ma - 1.0));
  mmrl_controller_destroy(c);
  return 0;
}
