// Joint roles (hips, legs, feet, toes) found by name, and left/right mirror pairs.
//
// Names are matched case-insensitively after dropping any namespace prefix ("mixamorig:",
// "Armature|"). A side is read from a "Left"/"Right" word or an "L"/"R" token at either
// end ("UpperLeg_L", "Foot.L", "L_Foot", "l_foot", "LFoot", "LeftUpLeg"). The rest of the
// name, stripped of separators, is matched against per-role vocabularies:
//   upper leg: upleg, upperleg, thigh, hip (a sided "hip", only if nothing better)
//   lower leg: leg, lowerleg, lowleg, shin, calf, knee
//   foot:      foot, ankle
//   toe:       toe, toes, toebase, ball, toe0
// Each chain must be structurally consistent (lower leg below upper leg, and so on). The
// hips are the nearest common ancestor of the two upper legs. A missing toe falls back to
// the foot's first child.
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
// Throws RoleError listing the skeleton's joints when a role cannot be found.
JointRoles skeleton_find_roles(const Skeleton& skeleton, const std::map<std::string, std::string>& overrides = {});

// Joint index of each role name, in joint_role_names() order.
std::vector<int> joint_roles_as_list(const JointRoles& roles);

// Side of a joint from its name: 0 left, 1 right, -1 none; base receives the name without
// the side token, lower case, separators removed.
int joint_side(const std::string& name, std::string* base = nullptr);

// For each joint, its mirror partner (same base name, other side), or itself.
std::vector<int> skeleton_mirror_map(const Skeleton& skeleton);

}  // namespace mmrl
