// size: the whole BVH reader (lexer, hierarchy, frames, units, import steps) and the forward
// kinematics it and its callers share.
#include "mmrl/bvh.hpp"

#include "mmrl/motion_import.hpp"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iomanip>
#include <sstream>
#include <unordered_set>

namespace mmrl {

int Skeleton::num_channels() const {
  int n = 0;
  for (const auto& c : channels) n += static_cast<int>(c.size());
  return n;
}

int Skeleton::find(const std::string& name) const {
  for (size_t i = 0; i < names.size(); ++i)
    if (names[i] == name) return static_cast<int>(i);
  return -1;
}

bool Skeleton::same_hierarchy(const Skeleton& o) const { return names == o.names && parents == o.parents; }

namespace {

// A cursor over the text that tracks line numbers. Tokens are separated by spaces, tabs,
// CR and LF.
class Lexer {
 public:
  Lexer(const std::string& text, const std::string& source) : s_(text), src_(source) {}

  [[noreturn]] void fail(const std::string& msg, int line = -1) const {
    throw BVHError(src_, line < 0 ? line_ : line, msg);
  }

  void skip_space() {
    while (pos_ < s_.size()) {
      const char c = s_[pos_];
      if (c == '\n') {
        ++line_;
        ++pos_;
      } else if (c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v') {
        ++pos_;
      } else {
        break;
      }
    }
  }

  // Next token; token_line() is its line. Empty at end of input.
  std::string next() {
    skip_space();
    tok_line_ = line_;
    const size_t b = pos_;
    while (pos_ < s_.size() && !is_space(s_[pos_])) ++pos_;
    return s_.substr(b, pos_ - b);
  }

  std::string expect_token(const char* what) {
    std::string t = next();
    if (t.empty()) fail(std::string("unexpected end of file, expected ") + what);
    return t;
  }

  // A joint name: the rest of the line after ROOT/JOINT, trimmed, internal spaces kept ("Bip01 L
  // Thigh"); a "{" that ends the line after a space is left for expect("{").
  std::string name_to_end_of_line(const char* keyword) {
    while (pos_ < s_.size() && (s_[pos_] == ' ' || s_[pos_] == '\t')) ++pos_;
    tok_line_ = line_;
    const size_t b = pos_;
    pos_ = std::min(s_.find('\n', b), s_.size());
    size_t e = pos_;
    while (e > b && is_space(s_[e - 1])) --e;
    if (e > b && s_[e - 1] == '{' && (e - 1 == b || is_space(s_[e - 2]))) {
      pos_ = --e;
      while (e > b && is_space(s_[e - 1])) --e;
    }
    if (e == b) fail(std::string(keyword) + " without a joint name", tok_line_);
    return s_.substr(b, e - b);
  }

  void expect(const char* keyword) {
    const std::string t = next();
    if (t.empty()) fail(std::string("unexpected end of file, expected '") + keyword + "'");
    if (t != keyword) fail(std::string("expected '") + keyword + "', found '" + t + "'", tok_line_);
  }

  float number(const char* what) {
    const std::string t = expect_token(what);
    return parse_number(t.data(), t.data() + t.size(), what, tok_line_);
  }

  int integer(const char* what) {
    const std::string t = expect_token(what);
    int v = 0;
    auto r = std::from_chars(t.data(), t.data() + t.size(), v);
    if (r.ec != std::errc() || r.ptr != t.data() + t.size())
      fail(std::string("expected an integer for ") + what + ", found '" + t + "'", tok_line_);
    return v;
  }

  float parse_number(const char* b, const char* e, const char* what, int line) const {
    float v = 0.0f;
    const char* p = b;
    if (p < e && *p == '+') ++p;  // from_chars refuses a leading '+'
    auto r = std::from_chars(p, e, v);
    if (r.ec == std::errc::result_out_of_range) fail(std::string("value out of range in ") + what, line);
    if (r.ec != std::errc() || r.ptr != e)
      fail(std::string("non-numeric value '") + std::string(b, e) + "' in " + what, line);
    if (!std::isfinite(v)) fail(std::string("NaN or infinite value '") + std::string(b, e) + "' in " + what, line);
    return v;
  }

  // The rest of the current line, for "Frame Time:" style headers.
  int token_line() const { return tok_line_; }
  int line() const { return line_; }
  size_t pos() const { return pos_; }
  const std::string& text() const { return s_; }

  static bool is_space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\f' || c == '\v'; }

 private:
  const std::string& s_;
  const std::string& src_;
  size_t pos_ = 0;
  int line_ = 1;
  int tok_line_ = 1;
};

bool parse_channel(const std::string& name, Channel* out) {
  static const char* kNames[6] = {"Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation"};
  for (int i = 0; i < 6; ++i) {
    if (name.size() == std::strlen(kNames[i])) {
      bool eq = true;
      for (size_t k = 0; k < name.size() && eq; ++k)
        eq = std::tolower(static_cast<unsigned char>(name[k])) == std::tolower(static_cast<unsigned char>(kNames[i][k]));
      if (eq) {
        *out = static_cast<Channel>(i);
        return true;
      }
    }
  }
  return false;
}

void check_text(const std::string& text, const std::string& source) {
  if (text.empty()) throw BVHError(source, 1, "empty file");
  // Binary content: a NUL byte or many control characters in the first 4 KiB.
  const size_t n = std::min<size_t>(text.size(), 4096);
  size_t control = 0;
  int line = 1;
  for (size_t i = 0; i < n; ++i) {
    const unsigned char c = static_cast<unsigned char>(text[i]);
    if (c == '\n') ++line;
    if (c == 0) throw BVHError(source, line, "binary file (NUL byte), not a BVH text file");
    if (c < 32 && c != '\n' && c != '\r' && c != '\t' && c != '\f' && c != '\v') ++control;
  }
  if (control * 20 > n) throw BVHError(source, 1, "binary file (control characters), not a BVH text file");
}

// Parses "JOINT name { ... }" recursively after the keyword and name are read.
void parse_joint(Lexer& lx, Skeleton& sk, int parent, const std::string& name, int name_line,
                 std::unordered_set<std::string>& seen) {
  if (!seen.insert(name).second) lx.fail("duplicate joint name '" + name + "'", name_line);
  const int index = sk.num_joints();
  sk.names.push_back(name);
  sk.parents.push_back(parent);
  sk.offsets.emplace_back(Vec3::Zero());
  sk.has_end_site.push_back(0);
  sk.end_sites.emplace_back(Vec3::Zero());
  sk.channels.emplace_back();
  lx.expect("{");
  const int open_line = lx.token_line();
  bool have_offset = false;
  for (;;) {
    const std::string t = lx.next();
    if (t.empty()) lx.fail("unbalanced braces: '{' opened on line " + std::to_string(open_line) + " for joint '" + name + "' is never closed");
    if (t == "}") break;
    if (t == "OFFSET") {
      Vec3 o;
      for (int k = 0; k < 3; ++k) o[k] = lx.number("OFFSET");
      sk.offsets[index] = o;
      have_offset = true;
    } else if (t == "CHANNELS") {
      const int line = lx.token_line();
      const int n = lx.integer("CHANNELS count");
      if (n < 0 || n > 6) lx.fail("CHANNELS count must be between 0 and 6, got " + std::to_string(n), line);
      std::vector<Channel> ch;
      for (int k = 0; k < n; ++k) {
        const std::string cname = lx.expect_token("a channel name");
        Channel c;
        if (!parse_channel(cname, &c)) {
          if (cname == "}" || cname == "JOINT" || cname == "End" || cname == "OFFSET")
            lx.fail("CHANNELS declares " + std::to_string(n) + " channels but lists " + std::to_string(k), line);
          lx.fail("unknown channel name '" + cname + "'", lx.token_line());
        }
        if (std::find(ch.begin(), ch.end(), c) != ch.end()) lx.fail("channel '" + cname + "' listed twice", lx.token_line());
        ch.push_back(c);
      }
      sk.channels[index] = ch;
    } else if (t == "JOINT") {
      const std::string child = lx.name_to_end_of_line("JOINT");
      const int child_line = lx.token_line();
      parse_joint(lx, sk, index, child, child_line, seen);
    } else if (t == "End") {
      lx.expect("Site");
      lx.expect("{");
      const int es_line = lx.token_line();
      Vec3 o = Vec3::Zero();
      for (;;) {
        const std::string u = lx.next();
        if (u.empty()) lx.fail("unbalanced braces: End Site '{' opened on line " + std::to_string(es_line) + " is never closed");
        if (u == "}") break;
        if (u == "OFFSET") {
          for (int k = 0; k < 3; ++k) o[k] = lx.number("End Site OFFSET");
        } else {
          lx.fail("unexpected '" + u + "' in End Site", lx.token_line());
        }
      }
      sk.has_end_site[index] = 1;
      sk.end_sites[index] = o;
    } else if (t == "MOTION" || t == "ROOT" || t == "HIERARCHY") {
      lx.fail("unbalanced braces: '" + t + "' inside joint '" + name + "' (opened on line " + std::to_string(open_line) + ")", lx.token_line());
    } else {
      lx.fail("unexpected '" + t + "' in joint '" + name + "'", lx.token_line());
    }
  }
  if (!have_offset) lx.fail("joint '" + name + "' has no OFFSET", name_line);
}

void fk_file_units_first_frame(const Motion& m, std::vector<float>& gp) {
  const int J = m.skeleton.num_joints();
  gp.resize(static_cast<size_t>(J) * 3);
  std::vector<float> gr(static_cast<size_t>(J) * 4);
  pose_forward_kinematics(m.skeleton.parents, m.translations.data(), m.rotations.data(), gp.data(), gr.data());
}

}  // namespace

float bvh_infer_scale(const Motion& m) {
  const int J = m.skeleton.num_joints();
  if (J == 0 || m.num_frames == 0) return 1.0f;
  std::vector<float> gp;
  fk_file_units_first_frame(m, gp);
  float lo = INFINITY, hi = -INFINITY;
  for (int j = 0; j < J; ++j) {
    lo = std::min(lo, gp[j * 3 + 1]);
    hi = std::max(hi, gp[j * 3 + 1]);
    if (m.skeleton.has_end_site[j]) {
      const Quat q = [&] {
        // Global rotation of j is needed for the End Site; recompute cheaply via parents.
        Quat r = Quat::Identity();
        for (int k = j; k >= 0; k = m.skeleton.parents[k]) r = quat_load(&m.rotations[k * 4]) * r;
        return r;
      }();
      const Vec3 e = Vec3(gp[j * 3], gp[j * 3 + 1], gp[j * 3 + 2]) + q * m.skeleton.end_sites[j];
      lo = std::min(lo, e.y());
      hi = std::max(hi, e.y());
    }
  }
  // The floor is taken at y = 0 unless joints go below it.
  const float h = hi - std::min(lo, 0.0f);
  if (!(h > 0)) return 1.0f;
  const float candidates[4] = {1.0f, 0.01f, 0.0254f, 0.001f};
  float best = 1.0f, best_err = INFINITY;
  for (float s : candidates) {
    const float err = std::fabs(std::log(h * s / 1.5f));
    if (err < best_err) {
      best_err = err;
      best = s;
    }
  }
  return best;
}

namespace {

// HIERARCHY and the MOTION header (Frames, Frame Time); leaves the lexer at the end of the
// Frame Time line's number. Returns the line of 'Frames:' (for messages).
constexpr float kMaxFrameTime = 10.0f;  // seconds

int parse_header(Lexer& lx, Motion& m) {
  Skeleton& sk = m.skeleton;
  std::unordered_set<std::string> seen;
  {
    const std::string t = lx.next();
    if (t != "HIERARCHY") lx.fail("expected 'HIERARCHY' at the start of the file, found '" + t.substr(0, 40) + "'", lx.token_line());
  }
  bool have_motion = false;
  for (;;) {
    const std::string t = lx.next();
    if (t.empty()) break;
    if (t == "ROOT") {
      const std::string name = lx.name_to_end_of_line("ROOT");
      parse_joint(lx, sk, -1, name, lx.token_line(), seen);
    } else if (t == "MOTION") {
      have_motion = true;
      break;
    } else if (t == "}") {
      lx.fail("unbalanced braces: '}' without a matching '{'", lx.token_line());
    } else {
      lx.fail("expected 'ROOT' or 'MOTION', found '" + t.substr(0, 40) + "'", lx.token_line());
    }
  }
  if (sk.num_joints() == 0) lx.fail("no ROOT joint in HIERARCHY");
  if (!have_motion) lx.fail("missing MOTION section");

  lx.expect("Frames:");
  const int frames_line = lx.token_line();
  const int frames = lx.integer("Frames");
  if (frames <= 0) lx.fail("zero frames (Frames: " + std::to_string(frames) + ")", frames_line);
  {
    lx.expect("Frame");
    const std::string t = lx.expect_token("'Time:'");
    if (t != "Time:") lx.fail("expected 'Frame Time:', found 'Frame " + t + "'", lx.token_line());
  }
  const int ft_line = lx.token_line();
  const float frame_time = lx.number("Frame Time");
  if (!(frame_time > 0)) lx.fail("Frame Time must be positive", ft_line);
  // At most 10 s per frame (0.1 fps): mocap is never slower, and resampling a slower clip to
  // a normal rate multiplies its frames without bound (a 2-frame file with a Frame Time of
  // 3e8 s asked for 8.5e9 frames at 30 fps; found by cpp/fuzz/fuzz_bvh.cpp).
  if (frame_time > kMaxFrameTime)
    lx.fail("Frame Time " + std::to_string(frame_time) + " s is implausible (at most 10 s per frame)", ft_line);
  m.frame_time = frame_time;
  m.num_frames = frames;
  return frames_line;
}

// Local transform of joint j from its channel values (file units, degrees).
void apply_channels(const Skeleton& sk, int j, const float* values, float* tr, float* rot) {
  tr[0] = sk.offsets[j].x();
  tr[1] = sk.offsets[j].y();
  tr[2] = sk.offsets[j].z();
  Eigen::Quaterniond r = Eigen::Quaterniond::Identity();
  for (Channel ch : sk.channels[j]) {
    const float v = *values++;
    switch (ch) {
      case Channel::Xposition: tr[0] = v; break;
      case Channel::Yposition: tr[1] = v; break;
      case Channel::Zposition: tr[2] = v; break;
      case Channel::Xrotation: r = r * Eigen::AngleAxisd(v * M_PI / 180.0, Eigen::Vector3d::UnitX()); break;
      case Channel::Yrotation: r = r * Eigen::AngleAxisd(v * M_PI / 180.0, Eigen::Vector3d::UnitY()); break;
      case Channel::Zrotation: r = r * Eigen::AngleAxisd(v * M_PI / 180.0, Eigen::Vector3d::UnitZ()); break;
    }
  }
  r.normalize();
  quat_store(r.cast<float>(), rot);
}

// Frame data after the header: one frame per non-blank line, exactly C values each.
void parse_frames(Lexer& lx, const std::string& source, int frames_line, Motion& m) {
  const Skeleton& sk = m.skeleton;
  const int frames = m.num_frames;
  const int J = sk.num_joints();
  const int C = sk.num_channels();
  const std::string& s = lx.text();
  size_t p = lx.pos();
  int line = lx.line();
  // The header's frame count sizes the arrays below, so it is checked against the text first:
  // a frame line holds C values of at least one character and C - 1 separators, and lines are
  // separated by a newline, so F frames need at least 2 C F - 1 bytes (C = 0: no frame line can
  // exist). Without this a 300-byte file saying "Frames: 999999999" allocated 56 GB (found
  // by cpp/fuzz/fuzz_bvh.cpp; tests/fuzz/regressions/bvh/). The error is the same as a
  // truncation found while reading: at the last line of the file.
  const uint64_t left = s.size() - p;
  if (C == 0 || 2 * static_cast<uint64_t>(C) * static_cast<uint64_t>(frames) > left + 1) {
    const int last_line = line + static_cast<int>(std::count(s.begin() + p, s.end(), '\n'));
    throw BVHError(source, last_line,
                   "truncated MOTION data: 'Frames: " + std::to_string(frames) + "' (line " +
                       std::to_string(frames_line) + ") but the " + std::to_string(left) + " bytes after it cannot hold " +
                       (C == 0 ? std::string("frame lines of no channels") : "that many frame lines of " + std::to_string(C) + " values"));
  }
  m.translations.resize(static_cast<size_t>(frames) * J * 3);
  m.rotations.resize(static_cast<size_t>(frames) * J * 4);
  std::vector<float> values(static_cast<size_t>(C));

  // Skip the rest of the Frame Time line.
  while (p < s.size() && s[p] != '\n') {
    if (!Lexer::is_space(s[p])) throw BVHError(source, line, "unexpected text after Frame Time");
    ++p;
  }
  int f = 0;
  while (p < s.size()) {
    // p is at '\n' (end of the previous line) or the start of a line.
    if (s[p] == '\n') {
      ++p;
      ++line;
      continue;
    }
    const size_t eol = std::min(s.find('\n', p), s.size());
    int count = 0;
    size_t q = p;
    bool blank = true;
    while (q < eol) {
      while (q < eol && Lexer::is_space(s[q])) ++q;
      if (q >= eol) break;
      size_t e = q;
      while (e < eol && !Lexer::is_space(s[e])) ++e;
      blank = false;
      if (f >= frames) throw BVHError(source, line, "more frame lines than 'Frames: " + std::to_string(frames) + "'");
      if (count < C) values[count] = lx.parse_number(s.data() + q, s.data() + e, "frame data", line);
      ++count;
      q = e;
    }
    if (!blank) {
      if (count != C)
        throw BVHError(source, line, "frame line has " + std::to_string(count) + " values, expected " + std::to_string(C));
      // Apply the channels to joint transforms (file units, scaled later).
      const float* v = values.data();
      for (int j = 0; j < J; ++j) {
        const size_t o = static_cast<size_t>(f) * J + j;
        apply_channels(sk, j, v, &m.translations[o * 3], &m.rotations[o * 4]);
        v += sk.channels[j].size();
      }
      ++f;
    }
    p = eol;
  }
  if (f < frames)
    throw BVHError(source, line, "truncated MOTION data: 'Frames: " + std::to_string(frames) + "' (line " +
                                     std::to_string(frames_line) + ") but only " + std::to_string(f) + " frame lines");
}

void motion_apply_scale(Motion& m, float scale) {
  m.scale = scale;
  if (scale == 1.0f) return;
  for (float& v : m.translations) v *= scale;
  for (auto& o : m.skeleton.offsets) o *= scale;
  for (auto& o : m.skeleton.end_sites) o *= scale;
}

}  // namespace

Motion bvh_parse(const std::string& text, const std::string& source, const BVHImportOptions& options) {
  if (!std::isfinite(options.scale) || options.scale < 0)
    throw std::invalid_argument("scale must be positive (or 0 to infer it), got " + std::to_string(options.scale));
  if (!std::isfinite(options.fps) || options.fps < 0)
    throw std::invalid_argument("fps must be positive (or 0 to keep the file's), got " + std::to_string(options.fps));
  check_text(text, source);
  Lexer lx(text, source);
  Motion m;
  m.source = source;
  const int frames_line = parse_header(lx, m);
  parse_frames(lx, source, frames_line, m);
  m.source_fps = motion_nominal_fps(m);
  // Up axis before the scale: the unit rule measures the height along Y.
  m.source_up = options.up == UpAxis::Auto ? motion_detect_up_axis(m) : options.up;
  if (m.source_up == UpAxis::Z) motion_rotate_z_up_to_y_up(m);
  motion_apply_scale(m, options.scale > 0 ? options.scale : bvh_infer_scale(m));
  if (options.fps > 0 && motion_needs_resample(m, options.fps)) m = motion_resample(m, options.fps);
  return m;
}

Motion bvh_load(const std::string& path, const BVHImportOptions& options) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw BVHError(path, 0, "cannot open file");
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) throw BVHError(path, 0, "read error");
  return bvh_parse(text, path, options);
}

void pose_forward_kinematics(const std::vector<int>& parents, const float* lt, const float* lr, float* gp, float* gr) {
  const int J = static_cast<int>(parents.size());
  for (int j = 0; j < J; ++j) {
    const Vec3 t(lt[j * 3], lt[j * 3 + 1], lt[j * 3 + 2]);
    const Quat r = quat_load(lr + j * 4);
    const int p = parents[j];
    if (p < 0) {
      gp[j * 3] = t.x();
      gp[j * 3 + 1] = t.y();
      gp[j * 3 + 2] = t.z();
      quat_store(r, gr + j * 4);
    } else {
      const Quat pr = quat_load(gr + p * 4);
      const Vec3 pos = Vec3(gp[p * 3], gp[p * 3 + 1], gp[p * 3 + 2]) + pr * t;
      gp[j * 3] = pos.x();
      gp[j * 3 + 1] = pos.y();
      gp[j * 3 + 2] = pos.z();
      quat_store((pr * r).normalized(), gr + j * 4);
    }
  }
}

void motion_forward_kinematics(const Motion& m, float* global_positions, float* global_rotations) {
  const int J = m.skeleton.num_joints();
  std::vector<float> gp(static_cast<size_t>(J) * 3), gr(static_cast<size_t>(J) * 4);
  for (int f = 0; f < m.num_frames; ++f) {
    const size_t o = static_cast<size_t>(f) * J;
    pose_forward_kinematics(m.skeleton.parents, &m.translations[o * 3], &m.rotations[o * 4], gp.data(), gr.data());
    if (global_positions) std::copy(gp.begin(), gp.end(), global_positions + o * 3);
    if (global_rotations) std::copy(gr.begin(), gr.end(), global_rotations + o * 4);
  }
}

}  // namespace mmrl
