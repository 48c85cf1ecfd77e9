// Tags on clips and requests over them (tags.hpp).
#include "mmrl/tags.hpp"

#include <algorithm>
#include <cctype>
#include <set>
#include <stdexcept>

namespace mmrl {
namespace {

bool tag_char(char c) { return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.'; }

bool tag_word(const std::string& s) {
  return !s.empty() && std::all_of(s.begin(), s.end(), tag_char);
}

std::string trim(const std::string& s) {
  size_t b = 0, e = s.size();
  while (b < e && std::isspace(static_cast<unsigned char>(s[b]))) ++b;
  while (e > b && std::isspace(static_cast<unsigned char>(s[e - 1]))) --e;
  return s.substr(b, e - b);
}

std::vector<std::string> split(const std::string& s, char sep) {
  std::vector<std::string> out;
  size_t b = 0;
  for (;;) {
    const size_t e = s.find(sep, b);
    out.push_back(trim(s.substr(b, e == std::string::npos ? std::string::npos : e - b)));
    if (e == std::string::npos) return out;
    b = e + 1;
  }
}

std::string group_of(const std::string& tag) { return tag.substr(0, tag.find('=')); }
std::string value_of(const std::string& tag) { return tag.substr(tag.find('=') + 1); }

}  // namespace

void check_tags(const std::vector<std::string>& tag_names, const std::vector<uint8_t>& clip_tags, int num_clips) {
  std::set<std::string> seen;
  for (const std::string& t : tag_names) {
    const size_t eq = t.find('=');
    if (eq == std::string::npos || !tag_word(t.substr(0, eq)) || !tag_word(t.substr(eq + 1)))
      throw std::invalid_argument("tag '" + t + "' is not group=value (letters, digits, '_', '-', '.')");
    if (!seen.insert(t).second) throw std::invalid_argument("tag '" + t + "' is listed twice");
  }
  if (clip_tags.size() != tag_names.size() * static_cast<size_t>(num_clips))
    throw std::invalid_argument("clip_tags has " + std::to_string(clip_tags.size()) + " values, expected " +
                                std::to_string(num_clips) + " clips x " + std::to_string(tag_names.size()) + " tags");
  for (uint8_t v : clip_tags)
    if (v > 1) throw std::invalid_argument("clip_tags must hold 0 or 1");
}

std::vector<std::string> tag_groups(const Database& db) {
  std::vector<std::string> groups;
  for (const std::string& t : db.tag_names) {
    const std::string g = group_of(t);
    if (std::find(groups.begin(), groups.end(), g) == groups.end()) groups.push_back(g);
  }
  return groups;
}

std::vector<int> group_tags(const Database& db, const std::string& group) {
  std::vector<int> out;
  for (size_t t = 0; t < db.tag_names.size(); ++t)
    if (group_of(db.tag_names[t]) == group) out.push_back(static_cast<int>(t));
  return out;
}

std::string tags_available(const Database& db) {
  if (db.tag_names.empty()) return "the database has no tags (add them with 'mmrl db build --tag-folder/--tag-pattern/--tags')";
  std::string out = "tags available: ";
  bool first_group = true;
  for (const std::string& g : tag_groups(db)) {
    out += (first_group ? "" : "; ") + g + "=";
    first_group = false;
    bool first = true;
    for (int t : group_tags(db, g)) {
      out += (first ? "" : "|") + value_of(db.tag_names[t]);
      first = false;
    }
  }
  return out;
}

TagRequest parse_request(const Database& db, const std::string& text) {
  TagRequest r;
  const std::string body = trim(text);
  if (body.empty() || body == "*") return r;
  std::vector<std::string> groups_seen;
  std::vector<std::string> canon;
  for (const std::string& term : split(body, '&')) {
    const size_t eq = term.find('=');
    if (term.empty() || eq == std::string::npos)
      throw std::invalid_argument("request '" + text + "': '" + term + "' is not group=value; " + tags_available(db));
    const std::string group = trim(term.substr(0, eq));
    if (std::find(groups_seen.begin(), groups_seen.end(), group) != groups_seen.end())
      throw std::invalid_argument("request '" + text + "': group '" + group + "' is named twice (use " + group +
                                  "=a|b for a choice)");
    groups_seen.push_back(group);
    if (group_tags(db, group).empty())
      throw std::invalid_argument("request '" + text + "': no tag group '" + group + "'; " + tags_available(db));
    std::vector<int> ids;
    std::string values;
    for (const std::string& value : split(term.substr(eq + 1), '|')) {
      const std::string name = group + "=" + value;
      const auto it = std::find(db.tag_names.begin(), db.tag_names.end(), name);
      if (value.empty() || it == db.tag_names.end())
        throw std::invalid_argument("request '" + text + "': no tag '" + name + "'; " + tags_available(db));
      const int id = static_cast<int>(it - db.tag_names.begin());
      if (std::find(ids.begin(), ids.end(), id) == ids.end()) {
        ids.push_back(id);
        values += (values.empty() ? "" : "|") + value;
      }
    }
    r.terms.push_back(ids);
    canon.push_back(group + "=" + values);
  }
  for (size_t k = 0; k < canon.size(); ++k) r.text += (k ? " & " : "") + canon[k];
  return r;
}

int64_t RequestSelection::start_frame(int64_t k) const {
  const size_t c = static_cast<size_t>(std::upper_bound(starts_before.begin() + 1, starts_before.end(), k) -
                                       (starts_before.begin() + 1));
  return first_start[c] + (k - starts_before[c]);
}

namespace {

// Fills the per-clip start runs of s from db.valid over the clips s allows.
void index_starts(const Database& db, RequestSelection& s) {
  for (int c = 0; c < db.num_clips(); ++c) {
    if (s.restricts() && !s.clip_mask[static_cast<size_t>(c)]) continue;
    int64_t first = -1, count = 0;
    for (int64_t f = db.clip_ranges[c * 2]; f < db.clip_ranges[c * 2 + 1]; ++f)
      if (db.valid[f]) {
        if (first < 0) first = f;
        if (f != first + count) throw std::logic_error("a clip's valid frames are not one run");
        ++count;
      }
    if (count == 0) continue;
    s.first_start.push_back(first);
    s.starts_before.push_back(s.starts_before.back() + count);
  }
}

}  // namespace

RequestSelection select_request(const Database& db, const TagRequest& request) {
  RequestSelection s;
  s.request = request;
  if (request.terms.empty()) {
    index_starts(db, s);
    return s;
  }
  const size_t C = static_cast<size_t>(db.num_clips()), T = db.tag_names.size();
  s.clip_mask.assign(C, 0);
  for (size_t c = 0; c < C; ++c) {
    bool ok = true;
    for (const auto& term : request.terms) {
      bool any = false;
      for (int t : term) any = any || db.clip_tags[c * T + static_cast<size_t>(t)] != 0;
      ok = ok && any;
    }
    s.clip_mask[c] = ok ? 1 : 0;
  }
  index_starts(db, s);
  if (s.num_start_frames() == 0)
    throw std::invalid_argument("request '" + request.text + "' selects no frame that can be matched (no clip carries all of it, "
                                "or its clips are shorter than the trajectory's second); " + tags_available(db));
  return s;
}

RequestSelection select_request(const Database& db, const std::string& text) {
  return select_request(db, parse_request(db, text));
}

RequestCode::RequestCode(const Database& db, const std::vector<std::string>& groups) {
  for (const std::string& g : groups) {
    if (std::find(groups_.begin(), groups_.end(), g) != groups_.end())
      throw std::invalid_argument("request_groups: group '" + g + "' is named twice");
    const std::vector<int> ids = group_tags(db, g);
    if (ids.empty()) throw std::invalid_argument("request_groups: no tag group '" + g + "'; " + tags_available(db));
    groups_.push_back(g);
    tags_.push_back(ids);
    dim_ += static_cast<int>(ids.size());
  }
}

void RequestCode::encode(const TagRequest& request, float* out) const {
  std::fill(out, out + dim_, 0.0f);
  int o = 0;
  for (const auto& ids : tags_) {
    for (const auto& term : request.terms)
      for (int t : term) {
        const auto it = std::find(ids.begin(), ids.end(), t);
        if (it != ids.end()) out[o + (it - ids.begin())] = 1.0f;
      }
    o += static_cast<int>(ids.size());
  }
}

size_t RequestMix::pick(double u) const {
  const auto it = std::upper_bound(cumulative.begin(), cumulative.end(), u);
  return std::min(static_cast<size_t>(it - cumulative.begin()), selections.size() - 1);
}

RequestMix request_mix(const Database& db, const RequestCode& code, float any_probability) {
  RequestMix mix;
  if (code.groups().empty()) return mix;
  if (!(any_probability >= 0.0f && any_probability <= 1.0f))
    throw std::invalid_argument("request_any must be in [0, 1], got " + std::to_string(any_probability));
  const size_t G = code.groups().size();
  std::vector<std::vector<int>> options(G);  // per group: -1 (free) and its tags
  size_t combos = 1;
  for (size_t g = 0; g < G; ++g) {
    if (any_probability > 0) options[g].push_back(-1);
    if (any_probability < 1)
      for (int t : group_tags(db, code.groups()[g])) options[g].push_back(t);
    combos *= options[g].size();
    if (combos > 4096) throw std::invalid_argument("request_groups: more than 4096 combinations of tags");
  }
  std::vector<double> weights;
  std::vector<size_t> digit(G, 0);
  for (size_t n = 0; n < combos; ++n) {
    size_t k = n;
    double w = 1;
    std::string text;
    for (size_t g = 0; g < G; ++g) {
      digit[g] = k % options[g].size();
      k /= options[g].size();
      const int t = options[g][digit[g]];
      const double values = static_cast<double>(options[g].size() - (any_probability > 0 ? 1 : 0));
      w *= t < 0 ? any_probability : (1.0 - any_probability) / values;
      if (t >= 0) text += (text.empty() ? "" : " & ") + db.tag_names[static_cast<size_t>(t)];
    }
    RequestSelection sel;
    try {
      sel = select_request(db, text);
    } catch (const std::invalid_argument&) {
      continue;  // selects no valid frame: left out
    }
    std::vector<float> c(static_cast<size_t>(code.dim()));
    code.encode(sel.request, c.data());
    mix.selections.push_back(std::move(sel));
    mix.codes.push_back(std::move(c));
    weights.push_back(w);
  }
  double total = 0;
  for (double w : weights) total += w;
  if (mix.selections.empty() || !(total > 0))
    throw std::invalid_argument("request_groups: no combination of tags selects a frame; " + tags_available(db));
  double acc = 0;
  for (double w : weights) mix.cumulative.push_back(acc += w / total);
  mix.cumulative.back() = 1.0;
  return mix;
}

}  // namespace mmrl
