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

bool is_sep(char c) { return c == '_' || c == '.' || c == '-' || c == ' ' || c == '\t' || c == ':'; }
bool is_upper(char c) { return std::isupper(static_cast<unsigned char>(c)) != 0; }
bool is_lower(char c) { return std::islower(static_cast<unsigned char>(c)) != 0; }
bool is_digit(char c) { return std::isdigit(static_cast<unsigned char>(c)) != 0; }

// A name's side (0 left, 1 right, -1 none) and its other tokens, lower case; sep_after[k]:
// tokens[k] ends at a separator or at the end of the name (not at a camel-case boundary).
struct NameParts {
  int side = -1;
  std::vector<std::string> tokens;
  std::vector<bool> sep_after;
  std::string base() const {
    std::string s;
    for (const auto& t : tokens) s += t;
    return s;
  }
  // The name is `word`: all its tokens (exact), or its last tokens after a prefix that ends at a
  // separator, such as "Bip01_" or "CC_Base_" (suffix; not "J" in "JLeftUpLeg").
  bool is(const std::string& word, bool exact) const {
    std::string s;
    for (size_t k = tokens.size(); k-- > (exact ? 0 : 1);) {
      s = tokens[k] + s;
      if (!exact && sep_after[k - 1] && s == word) return true;
    }
    return exact && s == word;
  }
};

// Splits a name (namespace dropped) into tokens at separators and at camel-case boundaries, that
// is before a capital that follows a lower-case letter or a digit, and before the last capital of
// a run that a lower-case letter follows ("LeftUpLeg" -> left up leg, "LFoot" -> l foot,
// "Bip01_L_Toe0" -> bip01 l toe0, "Toe0Nub" -> toe0 nub; digits stay with the token before them),
// then takes the side token out.
NameParts name_parts(const std::string& full_name) {
  const std::string name = strip_namespace(full_name);
  NameParts p;
  auto& t = p.tokens;
  std::string cur;
  auto flush = [&](bool at_sep) {
    if (!cur.empty()) {
      t.push_back(lower(cur));
      p.sep_after.push_back(at_sep);
    }
    cur.clear();
  };
  for (size_t i = 0; i < name.size(); ++i) {
    const char c = name[i];
    if (is_sep(c)) {
      flush(true);
      continue;
    }
    if (is_upper(c) && !cur.empty()) {
      const char b = name[i - 1];
      if (is_lower(b) || is_digit(b) || (is_upper(b) && i + 1 < name.size() && is_lower(name[i + 1]))) flush(false);
    }
    cur += c;
  }
  flush(true);
  // A side token anywhere: "L", "R", "Left", "Right" (the first one).
  for (size_t i = 0; i < t.size() && p.side < 0; ++i) {
    if (t[i] == "l" || t[i] == "left") p.side = 0;
    else if (t[i] == "r" || t[i] == "right") p.side = 1;
    if (p.side >= 0) {
      if (i > 0) p.sep_after[i - 1] = p.sep_after[i - 1] || p.sep_after[i];  // "Bip01_LThigh", "Bip01L_Thigh"
      t.erase(t.begin() + static_cast<std::ptrdiff_t>(i));
      p.sep_after.erase(p.sep_after.begin() + static_cast<std::ptrdiff_t>(i));
    }
  }
  // Glued lower case: "leftfoot", "footright".
  const char* words[2] = {"left", "right"};
  for (int s = 0; s < 2 && p.side < 0 && !t.empty(); ++s) {
    const std::string w = words[s];
    if (t.front().size() > w.size() && t.front().compare(0, w.size(), w) == 0) {
      p.side = s;
      t.front().erase(0, w.size());
    } else if (t.back().size() > w.size() && t.back().compare(t.back().size() - w.size(), w.size(), w) == 0) {
      p.side = s;
      t.back().erase(t.back().size() - w.size());
    }
  }
  return p;
}

bool descends_from(const Skeleton& sk, int j, int ancestor) {
  for (int k = sk.parents[j]; k >= 0; k = sk.parents[k])
    if (k == ancestor) return true;
  return false;
}

std::vector<NameParts> skeleton_name_parts(const Skeleton& sk) {
  std::vector<NameParts> parts;
  for (const auto& n : sk.names) parts.push_back(name_parts(n));
  return parts;
}

const std::vector<std::string> kHipsWords = {"hips", "pelvis", "hip"};

}  // namespace

int joint_side(const std::string& name, std::string* base) {
  const NameParts p = name_parts(name);
  if (base) *base = p.base();
  return p.side;
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

// The hips: the nearest joint without a side named hips, pelvis or hip at or above the nearest
// common ancestor of the two upper legs (Biped's Bip01_Pelvis above Bip01_Spine, which holds the
// thighs; not the Bip01 root above it); else that common ancestor, or its parent when it is itself
// a side joint. -1 when the upper legs have no common ancestor.
int find_hips(const Skeleton& sk, const std::vector<NameParts>& parts, int left_upper_leg, int right_upper_leg) {
  int common = -1;
  for (int a = sk.parents[left_upper_leg]; a >= 0 && common < 0; a = sk.parents[a])
    if (descends_from(sk, right_upper_leg, a)) common = a;
  if (common < 0) return -1;
  for (int a = common; a >= 0; a = sk.parents[a])
    for (const auto& w : kHipsWords)
      if (parts[a].side < 0 && (parts[a].is(w, true) || parts[a].is(w, false))) return a;
  return parts[common].side >= 0 ? sk.parents[common] : common;
}

// Every missing role in one error, with the command-line syntax that gives them.
void check_roles_found(const JointRoles& r, const std::string& joint_list) {
  const auto role_names = joint_role_names();
  const auto found = joint_roles_as_list(r);
  std::string missing, flags;
  int n = 0;
  for (size_t i = 0; i < found.size(); ++i)
    if (found[i] < 0) {
      missing += (n++ ? ", " : "") + role_names[i];
      flags += " --role " + role_names[i] + "=JOINT";
    }
  if (n > 0)
    throw RoleError("no joint found for " + std::string(n > 1 ? "roles " : "role ") + missing + "; pass " +
                    (n > 1 ? "them" : "it") + " as" + flags + "; joints found: " + joint_list);
}

}  // namespace

JointRoles skeleton_find_roles(const Skeleton& sk, const std::map<std::string, std::string>& overrides) {
  const int J = sk.num_joints();
  const std::vector<NameParts> parts = skeleton_name_parts(sk);

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
  auto over = [&](const std::string& role) {
    auto it = overrides.find(role);
    return it == overrides.end() ? -1 : sk.find(it->second);
  };

  // A joint on side s (-1: none) named by one of `words` (below `ancestor` if >= 0): whole
  // names first, best word first; then names that end in the word ("Bip01_L_Thigh").
  auto find_named = [&](int s, const std::vector<std::string>& words, int ancestor) {
    for (bool exact : {true, false})
      for (const auto& w : words)
        for (int j = 0; j < J; ++j)
          if (parts[j].side == s && parts[j].is(w, exact) && (ancestor < 0 || descends_from(sk, j, ancestor))) return j;
    return -1;
  };

  const std::vector<std::string> kLowerLeg = {"leg", "lowerleg", "lowleg", "shin", "calf", "knee"};
  JointRoles r;
  const char* side_name[2] = {"left", "right"};
  for (int s = 0; s < 2; ++s) {
    const std::string pre = std::string(side_name[s]) + "_";
    int ul = over(pre + "upper_leg");
    if (ul < 0) ul = find_named(s, {"upleg", "upperleg", "thigh", "uplegroll", "hip"}, -1);
    int ll = over(pre + "lower_leg");
    if (ll < 0) ll = find_named(s, kLowerLeg, ul);
    int ft = over(pre + "foot");
    if (ft < 0) ft = find_named(s, {"foot", "ankle"}, ll);
    int to = over(pre + "toe");
    if (to < 0) to = find_named(s, {"toe", "toes", "toebase", "ball", "toe0", "forefoot"}, ft);
    if (to < 0 && ft >= 0)
      for (int j = 0; j < J; ++j)
        if (sk.parents[j] == ft) {
          to = j;
          break;
        }
    // A "hip" joint right above the real upper leg (CMU's LHipJoint) is not the thigh.
    if (ul >= 0 && ll < 0) {
      int alt = find_named(s, kLowerLeg, -1);
      if (alt >= 0 && sk.parents[alt] >= 0 && sk.parents[sk.parents[alt]] == ul) {
        ul = sk.parents[alt];
        ll = alt;
        if (ft < 0) ft = find_named(s, {"foot", "ankle"}, ll);
      }
    }
    r.upper_leg[s] = ul;
    r.lower_leg[s] = ll;
    r.foot[s] = ft;
    r.toe[s] = to;
  }
  r.hips = over("hips");
  if (r.hips < 0)
    r.hips = r.upper_leg[0] >= 0 && r.upper_leg[1] >= 0 ? find_hips(sk, parts, r.upper_leg[0], r.upper_leg[1])
                                                        : find_named(-1, kHipsWords, -1);

  check_roles_found(r, joint_list());
  return r;
}

std::vector<int> skeleton_mirror_map(const Skeleton& sk, const JointRoles& roles) {
  const int J = sk.num_joints();
  const std::vector<NameParts> parts = skeleton_name_parts(sk);
  std::vector<int> map(J, -1);
  // Role joints pair by role, whatever their names say.
  if (roles.hips >= 0) map[roles.hips] = roles.hips;
  const std::pair<const int*, const char*> kinds[4] = {
      {roles.upper_leg, "upper_leg"}, {roles.lower_leg, "lower_leg"}, {roles.foot, "foot"}, {roles.toe, "toe"}};
  for (const auto& kind : kinds) {
    const int a = kind.first[0], b = kind.first[1];
    if (a < 0 || b < 0) continue;
    const std::string role = kind.second;
    if (a == b)
      throw RoleError("cannot mirror: left_" + role + " and right_" + role + " are the same joint '" + sk.names[a] + "'");
    for (int j : {a, b})
      if (map[j] >= 0 && map[j] != (j == a ? b : a))
        throw RoleError("cannot mirror: joint '" + sk.names[j] + "' has roles on both sides or pairs with two joints");
    map[a] = b;
    map[b] = a;
  }
  // The others by name: the same name with the other side's token; no side: the joint itself.
  for (int j = 0; j < J; ++j) {
    if (map[j] >= 0) continue;
    if (parts[j].side < 0) {
      map[j] = j;
      continue;
    }
    const std::string base = parts[j].base();
    for (int k = 0; k < J; ++k)
      if (map[k] < 0 && parts[k].side == 1 - parts[j].side && parts[k].base() == base) {
        map[j] = k;
        map[k] = j;
        break;
      }
  }
  std::string lonely;
  for (int j = 0; j < J; ++j)
    if (map[j] < 0) lonely += (lonely.empty() ? "'" : ", '") + sk.names[j] + (parts[j].side == 0 ? "' (left)" : "' (right)");
  if (!lonely.empty())
    throw RoleError("cannot mirror: no joint on the other side pairs with " + lonely +
                    " (a partner has the same name with the other side's L/R/Left/Right token, or is given by the "
                    "leg roles); rename the joints, or do not mirror");
  return map;
}

std::vector<int> skeleton_mirror_map(const Skeleton& sk) {
  JointRoles roles;
  try {
    roles = skeleton_find_roles(sk);
  } catch (const RoleError&) {
    // No leg roles: pair by name only.
  }
  return skeleton_mirror_map(sk, roles);
}

}  // namespace mmrl
