#include "mmrl/skeleton.hpp"

#include <algorithm>
#include <cctype>

namespace mmrl {

namespace {

std::string lower(const std::string& s) {
  std::string r = s;
  for (char& c : r) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return r;
}

std::string strip_namespace(const std::string& s) {
  const size_t p = s.find_last_of(":|");
  return p == std::string::npos ? s : s.substr(p + 1);
}

bool is_sep(char c) { return c == '_' || c == '.' || c == '-' || c == ' '; }

std::string strip_separators(const std::string& s) {
  std::string r;
  for (char c : s)
    if (!is_sep(c)) r += c;
  return r;
}

bool descends_from(const Skeleton& sk, int j, int ancestor) {
  for (int k = sk.parents[j]; k >= 0; k = sk.parents[k])
    if (k == ancestor) return true;
  return false;
}

}  // namespace

int joint_side(const std::string& full_name, std::string* base) {
  const std::string name = strip_namespace(full_name);
  const std::string lo = lower(name);
  int side = -1;
  std::string rest = lo;
  auto take = [&](int s, size_t b, size_t n) {
    side = s;
    rest = lo.substr(0, b) + lo.substr(b + n);
  };
  // Whole words first: "left"/"right" anywhere at a word start.
  if (lo.rfind("left", 0) == 0) take(0, 0, 4);
  else if (lo.rfind("right", 0) == 0) take(1, 0, 5);
  else if (lo.size() > 4 && lo.compare(lo.size() - 4, 4, "left") == 0) take(0, lo.size() - 4, 4);
  else if (lo.size() > 5 && lo.compare(lo.size() - 5, 5, "right") == 0) take(1, lo.size() - 5, 5);
  // Single-letter tokens separated from the rest: "L_", "_L", ".L", "l-".
  else if (lo.size() > 2 && (lo[0] == 'l' || lo[0] == 'r') && is_sep(lo[1])) take(lo[0] == 'l' ? 0 : 1, 0, 2);
  else if (lo.size() > 2 && (lo.back() == 'l' || lo.back() == 'r') && is_sep(lo[lo.size() - 2]))
    take(lo.back() == 'l' ? 0 : 1, lo.size() - 2, 2);
  // CamelCase prefix: "LFoot", "RUpLeg" (capital L/R followed by another capital).
  else if (name.size() > 2 && (name[0] == 'L' || name[0] == 'R') && std::isupper(static_cast<unsigned char>(name[1])))
    take(name[0] == 'L' ? 0 : 1, 0, 1);
  if (base) *base = strip_separators(rest);
  return side;
}

std::vector<std::string> joint_role_names() {
  return {"hips",      "left_upper_leg",  "left_lower_leg",  "left_foot",  "left_toe",
          "right_upper_leg", "right_lower_leg", "right_foot", "right_toe"};
}

std::vector<int> joint_roles_as_list(const JointRoles& r) {
  return {r.hips,         r.upper_leg[0], r.lower_leg[0], r.foot[0], r.toe[0],
          r.upper_leg[1], r.lower_leg[1], r.foot[1],      r.toe[1]};
}

namespace {

// The hips: the nearest common ancestor of the two upper legs (-1 if none), or its parent when
// that ancestor is itself a side joint (prefer the hips/pelvis on that path).
int find_hips(const Skeleton& sk, const std::vector<int>& side, int left_upper_leg, int right_upper_leg) {
  int hips = -1;
  for (int a = sk.parents[left_upper_leg]; a >= 0 && hips < 0; a = sk.parents[a])
    if (descends_from(sk, right_upper_leg, a)) hips = a;
  if (hips >= 0 && side[hips] >= 0) hips = sk.parents[hips];
  return hips;
}

}  // namespace

JointRoles skeleton_find_roles(const Skeleton& sk, const std::map<std::string, std::string>& overrides) {
  const int J = sk.num_joints();
  std::vector<int> side(J);
  std::vector<std::string> base(J);
  for (int j = 0; j < J; ++j) side[j] = joint_side(sk.names[j], &base[j]);

  auto joint_list = [&] {
    std::string s;
    for (int j = 0; j < J; ++j) s += (j ? ", " : "") + sk.names[j];
    return s;
  };
  const auto role_names = joint_role_names();
  for (const auto& kv : overrides) {
    if (std::find(role_names.begin(), role_names.end(), kv.first) == role_names.end())
      throw RoleError("unknown joint role '" + kv.first + "'; roles are hips, left_/right_ upper_leg, lower_leg, foot, toe");
    if (sk.find(kv.second) < 0)
      throw RoleError("role override " + kv.first + "='" + kv.second + "' names no joint; joints found: " + joint_list());
  }

  // Candidate joints of a role on a side, by vocabulary, best vocabulary word first.
  auto find_role = [&](int s, const std::vector<std::string>& words, int ancestor) {
    for (const auto& w : words)
      for (int j = 0; j < J; ++j)
        if (side[j] == s && base[j] == w && (ancestor < 0 || descends_from(sk, j, ancestor))) return j;
    return -1;
  };

  JointRoles r;
  const char* side_name[2] = {"left", "right"};
  for (int s = 0; s < 2; ++s) {
    const std::string pre = side_name[s];
    auto over = [&](const std::string& role) {
      auto it = overrides.find(pre + "_" + role);
      return it == overrides.end() ? -1 : sk.find(it->second);
    };
    int ul = over("upper_leg");
    if (ul < 0) ul = find_role(s, {"upleg", "upperleg", "thigh", "uplegroll", "hip"}, -1);
    int ll = over("lower_leg");
    if (ll < 0) ll = find_role(s, {"leg", "lowerleg", "lowleg", "shin", "calf", "knee"}, ul);
    int ft = over("foot");
    if (ft < 0) ft = find_role(s, {"foot", "ankle"}, ll);
    int to = over("toe");
    if (to < 0) to = find_role(s, {"toe", "toes", "toebase", "ball", "toe0", "forefoot"}, ft);
    if (to < 0 && ft >= 0)
      for (int j = 0; j < J; ++j)
        if (sk.parents[j] == ft) {
          to = j;
          break;
        }
    // A "hip" joint right above the real upper leg (CMU's LHipJoint) is not the thigh.
    if (ul >= 0 && ll < 0) {
      int alt = find_role(s, {"leg", "lowerleg", "lowleg", "shin", "calf", "knee"}, -1);
      if (alt >= 0 && sk.parents[alt] >= 0 && sk.parents[sk.parents[alt]] == ul) {
        ul = sk.parents[alt];
        ll = alt;
        if (ft < 0) ft = find_role(s, {"foot", "ankle"}, ll);
      }
    }
    const std::pair<int, const char*> parts[4] = {{ul, "upper_leg"}, {ll, "lower_leg"}, {ft, "foot"}, {to, "toe"}};
    for (const auto& p : parts)
      if (p.first < 0)
        throw RoleError("could not find the " + pre + " " + p.second + " joint by name (override it with " + pre + "_" +
                        p.second + "=JOINT); joints found: " + joint_list());
    r.upper_leg[s] = ul;
    r.lower_leg[s] = ll;
    r.foot[s] = ft;
    r.toe[s] = to;
  }

  auto it = overrides.find("hips");
  r.hips = it != overrides.end() ? sk.find(it->second) : find_hips(sk, side, r.upper_leg[0], r.upper_leg[1]);
  if (r.hips < 0) throw RoleError("could not find the hips (no common ancestor of the upper legs); joints found: " + joint_list());
  return r;
}

std::vector<int> skeleton_mirror_map(const Skeleton& sk) {
  const int J = sk.num_joints();
  std::vector<int> side(J), map(J);
  std::vector<std::string> base(J);
  for (int j = 0; j < J; ++j) {
    side[j] = joint_side(sk.names[j], &base[j]);
    map[j] = j;
  }
  for (int j = 0; j < J; ++j) {
    if (side[j] < 0) continue;
    for (int k = 0; k < J; ++k)
      if (side[k] == 1 - side[j] && base[k] == base[j]) {
        map[j] = k;
        break;
      }
  }
  return map;
}

}  // namespace mmrl
