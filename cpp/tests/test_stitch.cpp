// Inertialization: continuity at a transition and the decay of the offsets.
#include <gtest/gtest.h>

#include <cmath>

#include "mmrl/stitch.hpp"

using namespace mmrl;

namespace {

BlendPose pose(int J, float angle, const Vec3& hips) {
  BlendPose p;
  p.resize(J);
  for (int j = 0; j < J; ++j) p.rotations[j] = Quat(Eigen::AngleAxisf(angle * (j + 1), Vec3::UnitX()));
  p.hips_position = hips;
  p.hips_rotation = Quat(Eigen::AngleAxisf(angle, Vec3::UnitY()));
  return p;
}

}  // namespace

TEST(Spring, DecaysBelowOnePercentAfterFiveHalflives) {
  Vec3 x(1, -2, 0.5f), v = Vec3::Zero();
  const float halflife = 0.1f, dt = 1.0f / 30;
  for (int i = 0; i < 15; ++i) spring_decay(x, v, halflife, dt);  // 0.5 s
  EXPECT_LT(x.norm(), 0.01f * Vec3(1, -2, 0.5f).norm());
  // Exact solution at t: (x0 + y x0 t) e^{-y t}.
  Vec3 a(1, 0, 0), va = Vec3::Zero();
  spring_decay(a, va, halflife, 0.05f);
  const float y = 2 * std::log(2.0f) / halflife;
  EXPECT_NEAR(a.x(), (1 + y * 0.05f) * std::exp(-y * 0.05f), 1e-6f);
}

TEST(RotationVector, RoundTrip) {
  const Quat q(Eigen::AngleAxisf(1.2f, Vec3(1, 2, 3).normalized()));
  EXPECT_TRUE(quat_from_rotation_vector(quat_to_rotation_vector(q)).isApprox(q, 1e-5f));
  EXPECT_NEAR(quat_to_rotation_vector(q).norm(), 1.2f, 1e-5f);
  // The shortest path: -q is the same rotation.
  Quat nq = q;
  nq.coeffs() = -nq.coeffs();
  EXPECT_TRUE(quat_to_rotation_vector(nq).isApprox(quat_to_rotation_vector(q), 1e-5f));
}

TEST(Inertializer, NoJumpAtATransitionAndDecay) {
  const int J = 4, hips = 1;
  std::vector<bool> blended = {false, true, true, true};  // joint 0 is above the hips
  Inertializer in;
  in.reset(J, hips, blended, 0.1f);
  const BlendPose src = pose(J, 0.1f, Vec3(0.0f, 0.9f, 0.0f));
  const BlendPose dst = pose(J, 0.6f, Vec3(0.2f, 1.0f, -0.1f));
  BlendVelocity zero;
  zero.resize(J);
  in.transition(src, zero, dst, zero);
  // With no time elapsed the shown pose is the source pose.
  BlendPose out;
  out.resize(J);
  in.update(0.0f, dst, out);
  for (int j = 2; j < J; ++j) EXPECT_TRUE(out.rotations[j].isApprox(src.rotations[j], 1e-5f)) << j;
  EXPECT_TRUE(out.hips_position.isApprox(src.hips_position, 1e-5f));
  EXPECT_TRUE(out.hips_rotation.isApprox(src.hips_rotation, 1e-5f));
  EXPECT_TRUE(out.rotations[0].isApprox(dst.rotations[0]));  // not blended
  // A hard switch shows the destination at once.
  Inertializer hard;
  hard.reset(J, hips, blended, 0.0f);
  hard.transition(src, zero, dst, zero);
  hard.update(0.0f, dst, out);
  EXPECT_TRUE(out.hips_position.isApprox(dst.hips_position));
  // After 5 half-lives the offsets are below 1% of their start.
  const float start_rot = in.max_rotation_offset(), start_pos = in.hips_translation_offset();
  for (int i = 0; i < 15; ++i) in.update(1.0f / 30, dst, out);
  EXPECT_LT(in.max_rotation_offset(), 0.01f * start_rot);
  EXPECT_LT(in.hips_translation_offset(), 0.01f * start_pos);
}

TEST(Inertializer, RepeatedTransitionsStayContinuous) {
  const int J = 3;
  Inertializer in;
  in.reset(J, 0, {true, true, true}, 0.1f);
  BlendVelocity zero;
  zero.resize(J);
  const BlendPose a = pose(J, 0.0f, Vec3::Zero()), b = pose(J, 0.5f, Vec3(0.3f, 0, 0)), c = pose(J, -0.4f, Vec3(-0.2f, 0, 0));
  BlendPose out, before;
  out.resize(J);
  before.resize(J);
  in.transition(a, zero, b, zero);
  in.update(0.05f, b, before);
  // Second transition mid-decay: the shown pose must not move.
  in.transition(b, zero, c, zero);
  in.update(0.0f, c, out);
  EXPECT_TRUE(out.hips_position.isApprox(before.hips_position, 1e-5f));
  for (int j = 1; j < J; ++j) EXPECT_TRUE(out.rotations[j].isApprox(before.rotations[j], 1e-4f)) << j;
}
