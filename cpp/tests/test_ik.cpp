// Two-bone IK against hand-computed poses; every bad input is refused first.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "mmrl/ik.hpp"

using namespace mmrl;

namespace {

// A leg in the YZ plane: hip at 1 m, thigh 0.5 m down, shin 0.5 m down with the knee bent
// forward (+Z) by a few centimeters.
IkTwoBoneJob bent_leg() {
  IkTwoBoneJob job;
  job.hip = Vec3(0, 1.0f, 0);
  job.knee = Vec3(0, 0.5f, 0.05f);
  job.ankle = Vec3(0, 0.0f, 0.0f);
  job.margin = 0.015f;
  return job;
}

}  // namespace

TEST(IkTwoBone, RefusesBadInput) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  IkTwoBoneJob job = bent_leg();
  EXPECT_TRUE(job.Validate());
  job.target = Vec3(nan, 0, 0);
  EXPECT_FALSE(job.Validate());
  EXPECT_FALSE(job.Run());
  EXPECT_TRUE(job.hip_correction.isApprox(Quat::Identity()));
  job = bent_leg();
  job.knee = job.hip;  // zero-length thigh
  EXPECT_FALSE(job.Validate());
  job = bent_leg();
  job.margin = -0.01f;
  EXPECT_FALSE(job.Validate());
  job.margin = 0.6f;  // longer than a bone
  EXPECT_FALSE(job.Validate());
  job = bent_leg();
  job.pole_from_knee = false;
  job.pole = Vec3(0, nan, 0);
  EXPECT_FALSE(job.Validate());
}

TEST(IkTwoBone, ReachableTargetHandComputed) {
  IkTwoBoneJob job = bent_leg();
  const float upper = (job.knee - job.hip).norm(), lower = (job.ankle - job.knee).norm();
  // Target 0.8 m straight below the hip: the knee must sit where the law of cosines says,
  // in the plane of the current knee (+Z side).
  job.target = Vec3(0, 0.2f, 0);
  ASSERT_TRUE(job.Run());
  EXPECT_TRUE(job.reached);
  EXPECT_NEAR((job.new_ankle - job.target).norm(), 0.0f, 1e-5f);
  const float d = 0.8f;
  const float cos_a = (upper * upper + d * d - lower * lower) / (2 * upper * d);
  const Vec3 expected_knee = job.hip + upper * Vec3(0, -cos_a, std::sqrt(1 - cos_a * cos_a));
  EXPECT_NEAR((job.new_knee - expected_knee).norm(), 0.0f, 1e-5f);
  // The corrections rotate the bones onto the new positions and keep their lengths.
  const Vec3 thigh = job.hip_correction * (job.knee - job.hip);
  const Vec3 shin = job.knee_correction * (job.ankle - job.knee);
  EXPECT_NEAR((job.hip + thigh - job.new_knee).norm(), 0.0f, 1e-5f);
  EXPECT_NEAR((job.new_knee + shin - job.new_ankle).norm(), 0.0f, 1e-5f);
}

TEST(IkTwoBone, UnreachableTargetStopsShortByTheMargin) {
  IkTwoBoneJob job = bent_leg();
  const float upper = (job.knee - job.hip).norm(), lower = (job.ankle - job.knee).norm();
  job.target = Vec3(0, -2.0f, 0);  // 3 m below the hip
  ASSERT_TRUE(job.Run());
  EXPECT_FALSE(job.reached);
  // On the hip-target line at the reach, with the knee still bent forward.
  EXPECT_NEAR((job.new_ankle - Vec3(0, 1.0f - (upper + lower - 0.015f), 0)).norm(), 0.0f, 1e-5f);
  EXPECT_GT(job.new_knee.z(), 0.0f);
  EXPECT_NEAR((job.new_knee - job.hip).norm(), upper, 1e-5f);
  EXPECT_NEAR((job.new_ankle - job.new_knee).norm(), lower, 1e-5f);
}

TEST(IkTwoBone, ExplicitPoleChoosesTheBendingPlane) {
  IkTwoBoneJob job = bent_leg();
  job.target = Vec3(0, 0.3f, 0);
  job.pole_from_knee = false;
  job.pole = Vec3(1.0f, 0.5f, 0);  // bend toward +X
  ASSERT_TRUE(job.Run());
  EXPECT_GT(job.new_knee.x(), 0.05f);
  EXPECT_NEAR(job.new_knee.z(), 0.0f, 1e-5f);
  EXPECT_NEAR((job.new_ankle - job.target).norm(), 0.0f, 1e-5f);
}

TEST(IkTwoBone, StraightLegUsesTheFallbackDirection) {
  IkTwoBoneJob job;
  job.hip = Vec3(0, 1, 0);
  job.knee = Vec3(0, 0.5f, 0);
  job.ankle = Vec3(0, 0, 0);
  job.target = Vec3(0, 0.4f, 0);
  job.fallback_bend_direction = Vec3(0, 0, 1);
  ASSERT_TRUE(job.Run());
  EXPECT_GT(job.new_knee.z(), 0.1f);
  EXPECT_NEAR((job.new_ankle - job.target).norm(), 0.0f, 1e-5f);
}
