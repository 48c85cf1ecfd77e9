// Import steps against hand-computed references: the up axis, resampling, plausibility.
#include <gtest/gtest.h>

#include <cmath>

#include "mmrl/bvh.hpp"
#include "mmrl/motion_import.hpp"

using namespace mmrl;

namespace {

// A minimal biped named so that roles are found: Hips, legs, feet and toes, plus a head.
// `world` rotates the root (and its position), e.g. +90 degrees about X for a Z-up file.
// The root walks along +Z (Y-up world) at 1.5 m/s and turns at 0.8 rad/s about its own up.
constexpr int J = 10;

Motion biped(int frames, float fps, const Quat& world = Quat::Identity()) {
  Motion m;
  Skeleton& sk = m.skeleton;
  const char* names[J] = {"Hips",       "UpperLeg_L", "LowerLeg_L", "Foot_L", "Toes_L",
                          "UpperLeg_R", "LowerLeg_R", "Foot_R",     "Toes_R", "Head"};
  const int parents[J] = {-1, 0, 1, 2, 3, 0, 5, 6, 7, 0};
  const Vec3 offsets[J] = {{0, 0.9f, 0},  {0.1f, -0.05f, 0},  {0, -0.42f, 0}, {0, -0.4f, 0}, {0, -0.05f, 0.12f},
                           {-0.1f, -0.05f, 0}, {0, -0.42f, 0}, {0, -0.4f, 0}, {0, -0.05f, 0.12f}, {0, 0.7f, 0}};
  for (int j = 0; j < J; ++j) {
    sk.names.push_back(names[j]);
    sk.parents.push_back(parents[j]);
    sk.offsets.push_back(offsets[j]);
    sk.has_end_site.push_back(0);
    sk.end_sites.push_back(Vec3::Zero());
    sk.channels.push_back(j == 0 ? std::vector<Channel>{Channel::Xposition, Channel::Yposition, Channel::Zposition,
                                                        Channel::Zrotation, Channel::Xrotation, Channel::Yrotation}
                                 : std::vector<Channel>{Channel::Zrotation, Channel::Xrotation, Channel::Yrotation});
  }
  m.source = "biped.bvh";
  m.frame_time = 1.0f / fps;
  m.source_fps = fps;
  m.num_frames = frames;
  m.translations.resize(static_cast<size_t>(frames) * J * 3);
  m.rotations.resize(static_cast<size_t>(frames) * J * 4);
  for (int f = 0; f < frames; ++f) {
    const float t = f / fps;
    for (int j = 0; j < J; ++j) {
      Vec3 tr = offsets[j];
      Quat r = Quat(Eigen::AngleAxisf(0.3f * std::sin(3.0f * t + j), Vec3::UnitX()));  // leg swing
      if (j == 0) {
        tr = world * Vec3(0.2f, 0.9f + 0.03f * std::sin(6.0f * t), 1.5f * t);
        r = world * Quat(Eigen::AngleAxisf(0.8f * t, Vec3::UnitY()));
      }
      const size_t o = static_cast<size_t>(f) * J + j;
      for (int k = 0; k < 3; ++k) m.translations[o * 3 + k] = tr[k];
      quat_store(r, &m.rotations[o * 4]);
    }
  }
  return m;
}

std::string zeros(int n) {
  std::string s;
  for (int i = 0; i < n; ++i) s += " 0";
  return s;
}

std::vector<float> positions(const Motion& m) {
  std::vector<float> gp(static_cast<size_t>(m.num_frames) * m.skeleton.num_joints() * 3);
  motion_forward_kinematics(m, gp.data(), nullptr);
  return gp;
}

}  // namespace

TEST(UpAxis, DetectsAndUndoesZUp) {
  const Motion y_up = biped(40, 30.0f);
  Motion z_up = biped(40, 30.0f, Quat(Eigen::AngleAxisf(0.5f * kPi, Vec3::UnitX())));  // Y -> Z
  EXPECT_EQ(motion_detect_up_axis(y_up), UpAxis::Y);
  EXPECT_EQ(motion_detect_up_axis(z_up), UpAxis::Z);
  motion_rotate_z_up_to_y_up(z_up);
  EXPECT_EQ(motion_detect_up_axis(z_up), UpAxis::Y);
  const auto a = positions(y_up), b = positions(z_up);
  for (size_t i = 0; i < a.size(); ++i) ASSERT_NEAR(a[i], b[i], 1e-5f) << i;
}

TEST(UpAxis, WithoutRolesAssumesY) {
  Motion m = biped(5, 30.0f, Quat(Eigen::AngleAxisf(0.5f * kPi, Vec3::UnitX())));
  for (auto& n : m.skeleton.names) n = "J" + n;  // no role found by name
  m.skeleton.names[0] = "Root";
  EXPECT_EQ(motion_detect_up_axis(m), UpAxis::Y);
}

TEST(UpAxis, ParseRotatesBeforeInferringTheScale) {
  // A Z-up file in centimetres: 175 cm along Z. Read as Y up it would be 0 tall and keep scale 1.
  const std::string text =
      "HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n"
      " JOINT LeftUpLeg\n {\n  OFFSET 10 0 -5\n  CHANNELS 3 Zrotation Xrotation Yrotation\n"
      "  JOINT LeftLeg\n  {\n   OFFSET 0 0 -42\n   CHANNELS 3 Zrotation Xrotation Yrotation\n"
      "   JOINT LeftFoot\n   {\n    OFFSET 0 0 -42\n    CHANNELS 3 Zrotation Xrotation Yrotation\n"
      "    JOINT LeftToeBase\n    {\n     OFFSET 0 -10 -5\n     CHANNELS 3 Zrotation Xrotation Yrotation\n"
      "     End Site\n     {\n      OFFSET 0 -5 0\n     }\n    }\n   }\n  }\n }\n"
      " JOINT RightUpLeg\n {\n  OFFSET -10 0 -5\n  CHANNELS 3 Zrotation Xrotation Yrotation\n"
      "  JOINT RightLeg\n  {\n   OFFSET 0 0 -42\n   CHANNELS 3 Zrotation Xrotation Yrotation\n"
      "   JOINT RightFoot\n   {\n    OFFSET 0 0 -42\n    CHANNELS 3 Zrotation Xrotation Yrotation\n"
      "    JOINT RightToeBase\n    {\n     OFFSET 0 -10 -5\n     CHANNELS 3 Zrotation Xrotation Yrotation\n"
      "     End Site\n     {\n      OFFSET 0 -5 0\n     }\n    }\n   }\n  }\n }\n"
      " JOINT Head\n {\n  OFFSET 0 0 80\n  CHANNELS 3 Zrotation Xrotation Yrotation\n"
      "  End Site\n  {\n   OFFSET 0 0 0\n  }\n }\n}\nMOTION\nFrames: 1\nFrame Time: 0.0333333\n"
      "5 0 94" + zeros(30) + "\n";
  const Motion m = bvh_parse(text, "z.bvh");
  EXPECT_EQ(m.source_up, UpAxis::Z);
  EXPECT_FLOAT_EQ(m.scale, 0.01f);
  const auto gp = positions(m);
  EXPECT_NEAR(gp[1], 0.94f, 1e-5f);                   // hips 94 cm up, now along +Y
  EXPECT_NEAR(gp[9 * 3 + 1], 0.94f + 0.8f, 1e-5f);    // head above the hips
  EXPECT_NEAR(gp[0], 0.05f, 1e-6f);                   // x unchanged
  BVHImportOptions as_y;
  as_y.up = UpAxis::Y;
  EXPECT_EQ(bvh_parse(text, "z.bvh", as_y).source_up, UpAxis::Y);
}

TEST(Resample, SlerpAndLerpAreExactOnUniformMotion) {
  // Constant rates (linear translation, rotation at constant angular velocity about a fixed
  // axis) are reproduced exactly by lerp and slerp at any output time.
  const float src_fps = 24.0f, dst_fps = 30.0f;
  const int frames = 49;  // 2 s
  Motion m = biped(frames, src_fps);
  const Vec3 axis = Vec3(0.3f, 1.0f, -0.2f).normalized();
  for (int f = 0; f < frames; ++f) {
    const float t = f / src_fps;
    for (int j = 0; j < J; ++j) {
      const size_t o = static_cast<size_t>(f) * J + j;
      quat_store(Quat(Eigen::AngleAxisf(1.3f * t + 0.1f * j, axis)), &m.rotations[o * 4]);
      m.translations[o * 3 + 2] = 2.0f * t + j;
    }
  }
  const Motion r = motion_resample(m, dst_fps);
  EXPECT_EQ(r.num_frames, 61);  // floor(48 / 24 * 30) + 1
  EXPECT_FLOAT_EQ(r.fps(), dst_fps);
  EXPECT_FLOAT_EQ(r.source_fps, src_fps);
  for (int k = 0; k < r.num_frames; ++k) {
    const float t = k / dst_fps;
    for (int j = 0; j < J; ++j) {
      const size_t o = static_cast<size_t>(k) * J + j;
      const Quat want(Eigen::AngleAxisf(1.3f * t + 0.1f * j, axis));
      EXPECT_NEAR(std::fabs(quat_load(&r.rotations[o * 4]).dot(want)), 1.0f, 1e-6f) << k << " " << j;
      EXPECT_NEAR(r.translations[o * 3 + 2], 2.0f * t + j, 1e-5f) << k << " " << j;
    }
  }
}

TEST(Resample, IntegerRatioCopiesFramesAndRoundsFrameTime) {
  Motion m = biped(121, 60.0f);
  m.frame_time = 0.0166667f;  // as BVH files round it: the nominal rate is still 60
  EXPECT_FLOAT_EQ(motion_nominal_fps(m), 60.0f);
  EXPECT_TRUE(motion_needs_resample(m, 30.0f));
  EXPECT_FALSE(motion_needs_resample(m, 60.0f));
  const Motion r = motion_resample(m, 30.0f);
  ASSERT_EQ(r.num_frames, 61);
  for (int k = 0; k < r.num_frames; ++k)
    for (int c = 0; c < J * 4; ++c) ASSERT_EQ(r.rotations[k * J * 4 + c], m.rotations[2 * k * J * 4 + c]) << k;
  // Upsampling then downsampling gives the input back.
  const Motion up = motion_resample(r, 120.0f);
  EXPECT_EQ(up.num_frames, 241);
  const Motion back = motion_resample(up, 30.0f);
  ASSERT_EQ(back.num_frames, r.num_frames);
  for (size_t i = 0; i < r.translations.size(); ++i) ASSERT_EQ(back.translations[i], r.translations[i]);
  EXPECT_THROW(motion_resample(m, 0.0f), std::invalid_argument);
  EXPECT_THROW(motion_resample(m, NAN), std::invalid_argument);
}

TEST(Plausibility, UprightWalkerVersusLyingAndClimbing) {
  const MotionPlausibility ok = motion_plausibility(biped(91, 30.0f));
  EXPECT_NEAR(ok.seconds, 3.0f, 1e-5f);
  EXPECT_GT(ok.height, 1.3f);  // feet at ~0.03 m to the head at 1.6 m
  EXPECT_GT(ok.height, 2.0f * ok.horizontal_extent);  // upright: taller than wide
  EXPECT_LT(ok.vertical_travel, 0.1f);
  EXPECT_NEAR(ok.horizontal_path, 4.5f, 0.3f);  // 1.5 m/s for 3 s, plus the legs' swing
  // The same walker read with the wrong up axis (Y-up file rotated as if it were Z up):
  // lying on its back, its walk going straight down.
  Motion wrong = biped(91, 30.0f);
  motion_rotate_z_up_to_y_up(wrong);
  const MotionPlausibility bad = motion_plausibility(wrong);
  EXPECT_LT(bad.height, 0.5f * bad.horizontal_extent);
  EXPECT_NEAR(bad.vertical_travel, 4.5f, 0.1f);
  EXPECT_LT(bad.horizontal_path, 1.0f);
}
