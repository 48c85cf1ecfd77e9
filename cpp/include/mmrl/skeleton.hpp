// Joint roles (hips, legs, feet, toes) found by name, and left/right mirror pairs.
//
// Names are matched case-insensitively after dropping any namespace prefix ("mixamorig:",
// "Armature|"), split into tokens at separators (_ - . space :) and camel-case boundaries
// ("LeftUpLeg" -> left up leg, "LFoot" -> l foot, "Bip01 L Toe0" -> bip01 l toe0). A side is
// read from an "L"/"R"/"Left"/"Right" token anywhere in the name ("UpperLeg_L", "Foot.L",
// "l_foot", "LFoot", "lThigh", "LeftUpLeg", "Bip01_L_Thigh", "Bip01 R Calf"), or from
// "left"/"right" glued to either end of a lower-case name ("leftupleg"). The other tokens are
// matched against per-role vocabularies, whole names first, then names that end in the word
// after a prefix ("Bip01_L_Thigh", "CC_Base_L_Calf"):
//   hips:      hips, pelvis, hip (without a side)
//   upper leg: upleg, upperleg, thigh, uplegroll, hip (a sided "hip", only if nothing better)
//   lower leg: leg, lowerleg, lowleg, shin, calf, knee
//   foot:      foot, ankle
//   toe:       toe, toes, toebase, ball, toe0, forefoot
// Each chain must be structurally consistent (lower leg below upper leg, and so on). The
// hips are the nearest joint named hips/pelvis/hip at or above the nearest common ancestor of
// the two upper legs (Biped's thighs hang below Bip01_Spine, the hips are Bip01_Pelvis, not the
// Bip01 root), else that ancestor. A missing toe falls back to the foot's first child.
#pragma once

#include <map>
#include <stdexcept>
#include <string>
#include <vector>

#include "mmrl/bvh.hpp"

namespace mmrl {

class RoleError : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

struct JointRoles {
  // Index 0 is the left side, 1 the right side. -1 when unknown.
  int hips = -1;
  int upper_leg[2] = {-1, -1};
  int lower_leg[2] = {-1, -1};
  int foot[2] = {-1, -1};
  int toe[2] = {-1, -1};
};

// Role names used for overrides and reporting: "hips", "left_upper_leg", "left_lower_leg",
// "left_foot", "left_toe", and the same with "right_".
std::vector<std::string> joint_role_names();

// Finds the roles; `overrides` maps role names to joint names and wins over detection.
// Throws one RoleError naming every role that cannot be found, with the command-line syntax
// that gives them ("--role left_foot=JOINT") and the skeleton's joints.
JointRoles skeleton_find_roles(const Skeleton& skeleton, const std::map<std::string, std::string>& overrides = {});

// Joint index of each role name, in joint_role_names() order.
std::vector<int> joint_roles_as_list(const JointRoles& roles);

// Side of a joint from its name: 0 left, 1 right, -1 none; base receives the name without
// the side token, lower case, separators removed.
int joint_side(const std::string& name, std::string* base = nullptr);

// For each joint, its mirror partner, or itself for a joint without a side. The leg role
// joints pair by role (left_foot <-> right_foot, overrides included, whatever their names say),
// the others by name (the same base, the other side). Throws RoleError naming every joint with
// a side that nothing pairs with (mirroring it onto itself would put it on the wrong side), or
// a role given to the same joint on both sides.
std::vector<int> skeleton_mirror_map(const Skeleton& skeleton, const JointRoles& roles);
// The same with the roles found by name (skeleton_find_roles without overrides), or by name
// only when they cannot be found.
std::vector<int> skeleton_mirror_map(const Skeleton& skeleton);

}  // namespace mmrl
