// libFuzzer target: BVH text -> Motion (bvh_parse), then forward kinematics of every frame.
//
// The whole import runs: parse, up-axis detection (or a given up axis), the unit rule or a
// given scale, resampling to another frame rate. The first byte of the input picks the import
// options, the rest is the file, so one corpus covers every path; a seed written by
// tests/fuzz/make_corpus.py starts with the byte 0 (defaults: infer everything, keep the rate).
//
// A bad file must throw BVHError (or std::invalid_argument for bad options, never chosen
// here); anything else escaping, a crash, a leak or a sanitizer report is a finding.
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "mmrl/bvh.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  mmrl::BVHImportOptions options;
  const uint8_t flags = data[0];
  // bits 0-1: up axis (Auto, Y, Z); bit 2: scale 0.01 instead of inferred; bits 3-4: resample
  // to 0 (keep), 24, 30 or 60 fps.
  options.up = static_cast<mmrl::UpAxis>((flags & 3) % 3);
  if (flags & 4) options.scale = 0.01f;
  static const float kFps[4] = {0.0f, 24.0f, 30.0f, 60.0f};
  options.fps = kFps[(flags >> 3) & 3];
  const std::string text(reinterpret_cast<const char*>(data) + 1, size - 1);
  mmrl::Motion m;
  try {
    m = mmrl::bvh_parse(text, "fuzz.bvh", options);
  } catch (const mmrl::BVHError&) {
    return 0;
  }
  // A parsed motion is consistent: FK reads every array it promises.
  const size_t n = static_cast<size_t>(m.num_frames) * m.skeleton.num_joints();
  if (m.translations.size() != n * 3 || m.rotations.size() != n * 4) __builtin_trap();
  std::vector<float> gp(n * 3), gr(n * 4);
  mmrl::motion_forward_kinematics(m, gp.data(), gr.data());
  return 0;
}
