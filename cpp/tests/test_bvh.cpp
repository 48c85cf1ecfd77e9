// BVH parsing and forward kinematics against hand-computed poses.
#include <gtest/gtest.h>

#include "mmrl/bvh.hpp"
#include "mmrl/database.hpp"
#include "mmrl/skeleton.hpp"

using namespace mmrl;

namespace {

// Root with 6 channels and an OFFSET that position channels must replace; one child.
std::string two_joint_bvh(const std::string& child_channels, const std::string& frame) {
  return "HIERARCHY\nROOT Hips\n{\n\tOFFSET 100 0 0\n\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n"
         "\tJOINT Child\n\t{\n\t\tOFFSET 0 0 1\n\t\tCHANNELS 3 " + child_channels +
         "\n\t\tEnd Site\n\t\t{\n\t\t\tOFFSET 0 2 0\n\t\t}\n\t}\n}\nMOTION\nFrames: 1\nFrame Time: 0.1\n" + frame + "\n";
}

Vec3 joint_pos(const std::vector<float>& gp, int j) { return Vec3(gp[j * 3], gp[j * 3 + 1], gp[j * 3 + 2]); }

}  // namespace

TEST(Bvh, PositionChannelsReplaceOffset) {
  Motion m = bvh_parse(two_joint_bvh("Zrotation Xrotation Yrotation", "1 2 3 0 0 0 0 0 0"), "t.bvh", 1.0f);
  std::vector<float> gp(6);
  motion_forward_kinematics(m, gp.data(), nullptr);
  EXPECT_NEAR(joint_pos(gp, 0).x(), 1.0f, 1e-6f);  // not 101
  EXPECT_NEAR(joint_pos(gp, 1).z(), 4.0f, 1e-6f);
  EXPECT_FLOAT_EQ(m.fps(), 10.0f);
}

TEST(Bvh, RotationOrderFollowsChannelOrder) {
  // Rz(90) * Rx(90) * (0, 0, 1) = Rz(90) * (0, -1, 0) = (1, 0, 0).
  Motion zx = bvh_parse(two_joint_bvh("Zrotation Xrotation Yrotation", "0 0 0 0 0 0 90 90 0"), "zx.bvh", 1.0f);
  // Rx(90) * Rz(90) * (0, 0, 1) = Rx(90) * (0, 0, 1) = (0, -1, 0).
  Motion xz = bvh_parse(two_joint_bvh("Xrotation Zrotation Yrotation", "0 0 0 0 0 0 90 90 0"), "xz.bvh", 1.0f);
  std::vector<float> a(6), b(6);
  motion_forward_kinematics(zx, a.data(), nullptr);
  motion_forward_kinematics(xz, b.data(), nullptr);
  // The child sits at the root plus its offset rotated by the root; the root is unrotated.
  // The child's own rotation moves only its End Site, so check global rotations instead.
  std::vector<float> ra(8), rb(8);
  motion_forward_kinematics(zx, nullptr, ra.data());
  motion_forward_kinematics(xz, nullptr, rb.data());
  const Vec3 ea = quat_load(&ra[4]) * Vec3(0, 0, 1);
  const Vec3 eb = quat_load(&rb[4]) * Vec3(0, 0, 1);
  EXPECT_TRUE(ea.isApprox(Vec3(1, 0, 0), 1e-5f)) << ea.transpose();
  EXPECT_TRUE(eb.isApprox(Vec3(0, -1, 0), 1e-5f)) << eb.transpose();
}

TEST(Bvh, RootRotationMovesChildren) {
  // Root yaw of 90 degrees about Y maps the child offset (0, 0, 1) to (1, 0, 0).
  Motion m = bvh_parse(two_joint_bvh("Zrotation Xrotation Yrotation", "5 0 0 0 0 90 0 0 0"), "t.bvh", 1.0f);
  std::vector<float> gp(6);
  motion_forward_kinematics(m, gp.data(), nullptr);
  EXPECT_TRUE(joint_pos(gp, 1).isApprox(Vec3(6, 0, 0), 1e-5f)) << joint_pos(gp, 1).transpose();
}

TEST(Bvh, ErrorsNameFileAndLine) {
  std::string text = two_joint_bvh("Zrotation Xrotation Yrotation", "0 0 0 0 0 0 0 0");  // 8 of 9 values
  try {
    bvh_parse(text, "short.bvh", 1.0f);
    FAIL() << "expected BVHError";
  } catch (const BVHError& e) {
    EXPECT_EQ(e.file(), "short.bvh");
    EXPECT_EQ(e.line(), 19);
    EXPECT_NE(std::string(e.what()).find("short.bvh:19:"), std::string::npos) << e.what();
  }
}

TEST(Bvh, WriteThenParseRoundTrips) {
  Motion m = bvh_parse(two_joint_bvh("Yrotation Xrotation Zrotation", "1 2 3 10 20 30 -40 50 60"), "t.bvh", 0.01f);
  Motion r = bvh_parse(bvh_write(m), "r.bvh", 0.01f);
  ASSERT_EQ(r.num_frames, 1);
  for (size_t i = 0; i < m.translations.size(); ++i) EXPECT_NEAR(m.translations[i], r.translations[i], 1e-5f);
  for (int j = 0; j < 2; ++j) {
    const Quat a = quat_load(&m.rotations[j * 4]), b = quat_load(&r.rotations[j * 4]);
    EXPECT_NEAR(std::fabs(a.dot(b)), 1.0f, 1e-5f);
  }
}

TEST(Skeleton, RolesFromCommonConventions) {
  const std::vector<std::vector<std::string>> conventions = {
      {"Hips", "UpperLeg_L", "LowerLeg_L", "Foot_L", "Toes_L", "UpperLeg_R", "LowerLeg_R", "Foot_R", "Toes_R"},
      {"Hips", "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase", "RightUpLeg", "RightLeg", "RightFoot", "RightToeBase"},
      {"mixamorig:Hips", "mixamorig:LeftUpLeg", "mixamorig:LeftLeg", "mixamorig:LeftFoot", "mixamorig:LeftToeBase",
       "mixamorig:RightUpLeg", "mixamorig:RightLeg", "mixamorig:RightFoot", "mixamorig:RightToeBase"},
      {"pelvis", "thigh.L", "shin.L", "foot.L", "toe.L", "thigh.R", "shin.R", "foot.R", "toe.R"},
      {"Pelvis", "L_Thigh", "L_Calf", "L_Foot", "L_Toe", "R_Thigh", "R_Calf", "R_Foot", "R_Toe"},
      {"Hips", "LThigh", "LShin", "LFoot", "LToe", "RThigh", "RShin", "RFoot", "RToe"},
      {"hip", "thigh_l", "calf_l", "foot_l", "ball_l", "thigh_r", "calf_r", "foot_r", "ball_r"},
      // 3ds Max Biped: the side token inside the name, after the character's prefix.
      {"Bip01_Pelvis", "Bip01_L_Thigh", "Bip01_L_Calf", "Bip01_L_Foot", "Bip01_L_Toe0", "Bip01_R_Thigh",
       "Bip01_R_Calf", "Bip01_R_Foot", "Bip01_R_Toe0"},
      {"Bip01 Pelvis", "Bip01 L Thigh", "Bip01 L Calf", "Bip01 L Foot", "Bip01 L Toe0", "Bip01 R Thigh",
       "Bip01 R Calf", "Bip01 R Foot", "Bip01 R Toe0"},
      {"CC_Base_Pelvis", "CC_Base_L_Thigh", "CC_Base_L_Calf", "CC_Base_L_Foot", "CC_Base_L_ToeBase",
       "CC_Base_R_Thigh", "CC_Base_R_Calf", "CC_Base_R_Foot", "CC_Base_R_ToeBase"},
      {"hip", "lThigh", "lShin", "lFoot", "lToe", "rThigh", "rShin", "rFoot", "rToe"},
  };
  for (size_t c = 0; c < conventions.size(); ++c) {
    const auto& n = conventions[c];
    Skeleton sk;
    // hips(0) -> [1..4] left chain, [5..8] right chain
    const int parents[9] = {-1, 0, 1, 2, 3, 0, 5, 6, 7};
    for (int j = 0; j < 9; ++j) {
      sk.names.push_back(n[j]);
      sk.parents.push_back(parents[j]);
    }
    JointRoles r = skeleton_find_roles(sk);
    EXPECT_EQ(r.hips, 0) << n[0];
    EXPECT_EQ(r.upper_leg[0], 1) << n[1];
    EXPECT_EQ(r.lower_leg[0], 2) << n[2];
    EXPECT_EQ(r.foot[0], 3) << n[3];
    EXPECT_EQ(r.toe[0], 4) << n[4];
    EXPECT_EQ(r.upper_leg[1], 5);
    EXPECT_EQ(r.toe[1], 8);
    const auto mirror = skeleton_mirror_map(sk);
    EXPECT_EQ(mirror[1], 5);
    EXPECT_EQ(mirror[8], 4);
    EXPECT_EQ(mirror[0], 0);
  }
}

TEST(Skeleton, BipedHipsArePelvisAboveTheSpineThatHoldsTheThighs) {
  // Biped's hierarchy: Bip01 > Bip01 Pelvis > Bip01 Spine > (thighs, Bip01 Spine1).
  Skeleton sk;
  sk.names = {"Bip01", "Bip01 Pelvis", "Bip01 Spine", "Bip01 L Thigh", "Bip01 L Calf", "Bip01 L Foot", "Bip01 L Toe0",
              "Bip01 R Thigh", "Bip01 R Calf", "Bip01 R Foot", "Bip01 R Toe0", "Bip01 Spine1"};
  sk.parents = {-1, 0, 1, 2, 3, 4, 5, 2, 7, 8, 9, 2};
  const JointRoles r = skeleton_find_roles(sk);
  EXPECT_EQ(r.hips, 1);
  EXPECT_EQ(r.upper_leg[0], 3);
  EXPECT_EQ(r.toe[1], 10);
  const auto mirror = skeleton_mirror_map(sk, r);
  EXPECT_EQ(mirror, (std::vector<int>{0, 1, 2, 7, 8, 9, 10, 3, 4, 5, 6, 11}));
}

TEST(Skeleton, MissingRolesAllInOneError) {
  Skeleton sk;
  sk.names = {"Root", "A", "B"};
  sk.parents = {-1, 0, 1};
  try {
    skeleton_find_roles(sk);
    FAIL();
  } catch (const RoleError& e) {
    const std::string m = e.what();
    EXPECT_EQ(m.rfind("no joint found for roles hips, left_upper_leg, left_lower_leg, left_foot, left_toe, "
                      "right_upper_leg, right_lower_leg, right_foot, right_toe; pass them as --role hips=JOINT "
                      "--role left_upper_leg=JOINT",
                      0),
              0u)
        << m;
    EXPECT_NE(m.find("--role right_toe=JOINT; joints found: Root, A, B"), std::string::npos) << m;
  }
}

TEST(Skeleton, MirrorPairsTheLegsByRoleOverrides) {
  // Names that pair the wrong joints (Leg1_L, the left upper leg, with Leg1_R, the right toe),
  // and a centre line without vocabulary: the overrides decide.
  Skeleton sk;
  sk.names = {"Root0", "Leg1_L", "Leg2_L", "Leg3_L", "Leg4_L", "Leg4_R", "Leg3_R", "Leg2_R", "Leg1_R", "Arm_L", "Arm_R"};
  sk.parents = {-1, 0, 1, 2, 3, 0, 5, 6, 7, 0, 0};
  const std::map<std::string, std::string> overrides = {
      {"hips", "Root0"},          {"left_upper_leg", "Leg1_L"},  {"left_lower_leg", "Leg2_L"},
      {"left_foot", "Leg3_L"},    {"left_toe", "Leg4_L"},        {"right_upper_leg", "Leg4_R"},
      {"right_lower_leg", "Leg3_R"}, {"right_foot", "Leg2_R"},   {"right_toe", "Leg1_R"}};
  const auto mirror = skeleton_mirror_map(sk, skeleton_find_roles(sk, overrides));
  EXPECT_EQ(mirror, (std::vector<int>{0, 5, 6, 7, 8, 1, 2, 3, 4, 10, 9}));
  // By name alone (no roles found), Leg1_L pairs with Leg1_R.
  EXPECT_EQ(skeleton_mirror_map(sk)[1], 8);
  // A side joint that nothing pairs with is an error, not a joint mirrored onto itself.
  sk.names[10] = "Wing_R";
  try {
    skeleton_mirror_map(sk);
    FAIL();
  } catch (const RoleError& e) {
    EXPECT_NE(std::string(e.what()).find("'Arm_L' (left), 'Wing_R' (right)"), std::string::npos) << e.what();
  }
}

TEST(Bvh, JointNamesWithSpaces) {
  std::string text = two_joint_bvh("Zrotation Xrotation Yrotation", "1 2 3 10 20 30 -40 50 60");
  text.replace(text.find("ROOT Hips"), 9, "ROOT Bip01 Pelvis \t");
  text.replace(text.find("JOINT Child"), 11, "JOINT Bip01  L Thigh");
  const Motion m = bvh_parse(text, "s.bvh", 1.0f);
  EXPECT_EQ(m.skeleton.names, (std::vector<std::string>{"Bip01 Pelvis", "Bip01  L Thigh"}));
  const Motion r = bvh_parse(bvh_write(m), "r.bvh", 1.0f);
  EXPECT_EQ(r.skeleton.names, m.skeleton.names);
}

TEST(Math, LocalWorldRoundTrip) {
  for (float yaw : {-2.5f, -0.3f, 0.0f, 1.0f, 3.0f}) {
    const Vec2 l = world_to_local_xz(0.3f, -1.7f, yaw);
    const Vec2 w = local_to_world_xz(l.x(), l.y(), yaw);
    EXPECT_NEAR(w.x(), 0.3f, 1e-5f);
    EXPECT_NEAR(w.y(), -1.7f, 1e-5f);
    // The character's own forward is +Z in its frame.
    const Vec3 f = forward_from_yaw(yaw);
    const Vec2 lf = world_to_local_xz(f.x(), f.z(), yaw);
    EXPECT_NEAR(lf.x(), 0.0f, 1e-6f);
    EXPECT_NEAR(lf.y(), 1.0f, 1e-6f);
  }
}
