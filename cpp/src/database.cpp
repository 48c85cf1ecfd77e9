#include "mmrl/database.hpp"

#include "mmrl/tags.hpp"

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace mmrl {

namespace {

// Whether joint j of m translates: a root, or a joint whose translation leaves its offset on
// some frame (position channels that only repeat the offset, as Bandai-Namco's, do not count).
bool translates(const Motion& m, int j) {
  const Skeleton& sk = m.skeleton;
  if (sk.parents[j] < 0) return true;
  const int J = sk.num_joints();
  for (int f = 0; f < m.num_frames; ++f) {
    const float* t = &m.translations[(static_cast<size_t>(f) * J + j) * 3];
    if (std::abs(t[0] - sk.offsets[j].x()) + std::abs(t[1] - sk.offsets[j].y()) + std::abs(t[2] - sk.offsets[j].z()) >
        1e-4f)
      return true;
  }
  return false;
}

Vec3 reflect(const Vec3& v) { return Vec3(-v.x(), v.y(), v.z()); }
Vec3 load3(const float* p) { return Vec3(p[0], p[1], p[2]); }

// The shortest rotation taking direction a to direction b (both nonzero).
Quat rotation_between(const Vec3& a, const Vec3& b) {
  Quat q;
  q.setFromTwoVectors(a, b);
  return q.normalized();
}

}  // namespace

std::vector<Quat> mirror_corrections(const std::vector<const Motion*>& clips, const std::vector<int>& map) {
  if (clips.empty()) throw std::invalid_argument("mirror_corrections: no clips");
  const Skeleton& sk = clips.front()->skeleton;
  const int J = sk.num_joints();
  // Each joint's fixed child offsets (children without position channels, and its end site)
  // and where the mirror must put them: the partner's matching offsets, reflected.
  std::vector<std::vector<std::pair<Vec3, Vec3>>> pairs(J);
  for (int c = 0; c < J; ++c) {
    const int p = sk.parents[c];
    if (p < 0 || std::any_of(clips.begin(), clips.end(), [&](const Motion* m) { return translates(*m, c); })) continue;
    pairs[p].emplace_back(sk.offsets[c], reflect(sk.offsets[map[c]]));
  }
  for (int j = 0; j < J; ++j)
    if (sk.has_end_site[j] && sk.has_end_site[map[j]]) pairs[j].emplace_back(sk.end_sites[j], reflect(sk.end_sites[map[j]]));
  for (auto& list : pairs)  // zero-length offsets fix no direction
    list.erase(std::remove_if(list.begin(), list.end(),
                              [](const std::pair<Vec3, Vec3>& q) { return q.first.norm() < 1e-6f || q.second.norm() < 1e-6f; }),
               list.end());
  std::vector<Quat> out(J, Quat::Identity());
  std::vector<bool> fitted(J, false);
  for (int j = 0; j < J; ++j) {
    if (pairs[j].size() < 2) continue;
    Eigen::Matrix3d h = Eigen::Matrix3d::Zero();
    for (const auto& [a, b] : pairs[j]) h += a.cast<double>() * b.cast<double>().transpose();
    Eigen::JacobiSVD<Eigen::Matrix3d> svd(h, Eigen::ComputeFullU | Eigen::ComputeFullV);
    const Eigen::Vector3d sv = svd.singularValues();
    if (!(sv(1) > 1e-6 * sv(0))) continue;  // collinear children: a direction, not a frame
    Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
    d(2, 2) = (svd.matrixV() * svd.matrixU().transpose()).determinant() < 0 ? -1.0 : 1.0;
    const Eigen::Matrix3d r = svd.matrixV() * d * svd.matrixU().transpose();
    out[j] = Quat(r.cast<float>()).normalized();
    fitted[j] = true;
  }
  // The rest: the mean over frames of M r_s(j)^-1 M C_p r_j (parents first), which for a
  // symmetric pose is exactly the correction that leaves its local rotations unchanged.
  std::vector<int> order(J);
  for (int j = 0; j < J; ++j) order[j] = j;
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    auto depth = [&](int x) {
      int d = 0;
      while (sk.parents[x] >= 0) x = sk.parents[x], ++d;
      return d;
    };
    return depth(a) < depth(b);
  });
  for (int j : order) {
    const int p = sk.parents[j];
    if (fitted[j] || p < 0) continue;  // a root without a fitted frame keeps the identity
    Eigen::Vector4d sum = Eigen::Vector4d::Zero();
    const Quat cp = out[p];
    for (const Motion* m : clips) {
      const int step = std::max(1, m->num_frames / 64);
      for (int f = 0; f < m->num_frames; f += step) {
        const float* r = &m->rotations[(static_cast<size_t>(f) * J) * 4];
        const Quat rj = quat_load(r + j * 4), rs = quat_load(r + map[j] * 4);
        const Quat q = (quat_mirror_x(rs).conjugate() * cp * rj).normalized();
        Eigen::Vector4d v(q.w(), q.x(), q.y(), q.z());
        if (v.dot(sum) < 0) v = -v;
        sum += v;
      }
    }
    Quat c = sum.norm() > 0 ? Quat(static_cast<float>(sum(0)), static_cast<float>(sum(1)), static_cast<float>(sum(2)),
                                   static_cast<float>(sum(3))).normalized()
                            : Quat::Identity();
    if (pairs[j].size() == 1) c = (rotation_between(c * pairs[j][0].first, pairs[j][0].second) * c).normalized();
    out[j] = c;
  }
  return out;
}

Motion motion_mirror(const Motion& m, const std::vector<int>& mirror_map) {
  return motion_mirror(m, mirror_map, mirror_corrections({&m}, mirror_map));
}

Motion motion_mirror(const Motion& m, const std::vector<int>& mirror_map, const std::vector<Quat>& corrections) {
  const int J = m.skeleton.num_joints();
  if (static_cast<int>(corrections.size()) != J || static_cast<int>(mirror_map.size()) != J)
    throw std::invalid_argument("motion_mirror: one mirror partner and one correction per joint");
  Motion out = m;
  out.source = m.source;
  std::vector<float> gp(static_cast<size_t>(J) * 3), gr(static_cast<size_t>(J) * 4);
  std::vector<Vec3> mp(J);
  std::vector<Quat> mr(J);
  std::vector<uint8_t> moves(J);
  for (int j = 0; j < J; ++j) moves[j] = translates(m, j);
  for (int f = 0; f < m.num_frames; ++f) {
    const size_t o = static_cast<size_t>(f) * J;
    pose_forward_kinematics(m.skeleton.parents, &m.translations[o * 3], &m.rotations[o * 4], gp.data(), gr.data());
    for (int j = 0; j < J; ++j) {
      const int s = mirror_map[j];
      mr[j] = (quat_mirror_x(quat_load(&gr[s * 4])) * corrections[j]).normalized();
    }
    // Global positions of the mirror, parents first: translating joints at the mirrored
    // positions, the others through their own (unchanged) offsets.
    for (int j = 0; j < J; ++j) {
      const int p = m.skeleton.parents[j];
      const int s = mirror_map[j];
      if (moves[j]) {
        mp[j] = Vec3(-gp[s * 3], gp[s * 3 + 1], gp[s * 3 + 2]);
      } else {
        mp[j] = mp[p] + mr[p] * load3(&m.translations[(o + j) * 3]);
      }
    }
    for (int j = 0; j < J; ++j) {
      const int p = m.skeleton.parents[j];
      Quat r = p < 0 ? mr[j] : (mr[p].conjugate() * mr[j]).normalized();
      quat_store(r, &out.rotations[(o + j) * 4]);
      if (!moves[j]) continue;  // fixed offsets stay the skeleton's
      const Vec3 t = p < 0 ? mp[j] : Vec3(mr[p].conjugate() * (mp[j] - mp[p]));
      float* tr = &out.translations[(o + j) * 3];
      tr[0] = t.x();
      tr[1] = t.y();
      tr[2] = t.z();
    }
  }
  return out;
}

static_assert(kPathSampleFrames[kPathSamples - 1] == kTrajectoryOffsets[2],
              "path samples end at the trajectory's last horizon, the frames a valid frame has left");

void Database::index_clips() {
  valid.assign(num_frames, 0);
  frame_clip.assign(num_frames, -1);
  const int C = static_cast<int>(clip_ranges.size() / 2);
  for (int c = 0; c < C; ++c) {
    const int b = clip_ranges[c * 2], e = clip_ranges[c * 2 + 1];
    for (int i = b; i < e; ++i) {
      frame_clip[i] = c;
      valid[i] = (i + kTrajectoryOffsets[2] < e) ? 1 : 0;
    }
  }
  valid_frames.clear();
  for (int64_t i = 0; i < num_frames; ++i)
    if (valid[i]) valid_frames.push_back(i);
  path_samples.assign(static_cast<size_t>(num_frames) * kPathSamples * 2, 0.0f);
  path_reach.fill(0.0f);
  if (root_positions.size() != static_cast<size_t>(num_frames) * 3 || root_yaws.size() != static_cast<size_t>(num_frames))
    return;  // validate() reports the sizes
  const float* rp = root_positions.data();
  const float* ry = root_yaws.data();
  for (int64_t i = 0; i < num_frames; ++i) {
    if (!valid[i]) continue;
    float* out = &path_samples[static_cast<size_t>(i) * kPathSamples * 2];
    for (int s = 0; s < kPathSamples; ++s) {
      const int64_t j = i + kPathSampleFrames[s];
      const Vec2 p = world_to_local_xz(rp[j * 3] - rp[i * 3], rp[j * 3 + 2] - rp[i * 3 + 2], ry[i]);
      out[2 * s] = p.x();
      out[2 * s + 1] = p.y();
      path_reach[s] = std::max(path_reach[s], std::hypot(p.x(), p.y()));
    }
  }
}

void Database::check_weights(const std::array<float, kNumBlocks>& w) {
  for (float x : w)
    if (!(x > 0) || !std::isfinite(x)) throw std::invalid_argument("feature block weights must be positive and finite");
}

void Database::set_weights(const std::array<float, kNumBlocks>& w) {
  check_weights(w);
  normalization.weights = w;
  std::vector<float> out(features.size());
  features_normalize(normalization, features.data(), num_frames, out.data());
  normalized = std::move(out);
}

void Database::refit_normalization() {
  normalization = features_fit_normalization(features.data(), num_frames, normalization.weights);
  set_weights(normalization.weights);
}

void Database::validate() const {
  const size_t N = num_frames, J = num_joints;
  auto need = [&](size_t got, size_t want, const char* what) {
    if (got != want)
      throw std::invalid_argument(std::string("database array '") + what + "' has " + std::to_string(got) +
                                  " values, expected " + std::to_string(want));
  };
  if (skeleton.num_joints() != num_joints) throw std::invalid_argument("database skeleton size mismatch");
  need(bone_translations.size(), N * J * 3, "bone_translations");
  need(bone_rotations.size(), N * J * 4, "bone_rotations");
  need(root_positions.size(), N * 3, "root_positions");
  need(root_yaws.size(), N, "root_yaws");
  need(root_deltas.size(), N * 3, "root_deltas");
  need(features.size(), N * kFeatureDim, "features");
  need(clip_names.size() * 2, clip_ranges.size(), "clip_ranges");
  need(clip_mirrored.size(), clip_names.size(), "clip_mirrored");
  int prev = 0;
  for (size_t c = 0; c < clip_names.size(); ++c) {
    const int b = clip_ranges[c * 2], e = clip_ranges[c * 2 + 1];
    if (b != prev || e <= b || e > num_frames) throw std::invalid_argument("database clip_ranges are not contiguous");
    prev = e;
  }
  if (prev != num_frames) throw std::invalid_argument("database clip_ranges do not cover all frames");
  need(contacts.size(), N * 2, "contacts");
  check_tags(tag_names, clip_tags, num_clips());
  for (float v : features)
    if (!std::isfinite(v)) throw std::invalid_argument("database features contain NaN or inf");
  for (int p : skeleton.parents)
    if (p >= num_joints) throw std::invalid_argument("database skeleton parent index out of range");
}

void database_compute_contacts(Database& db, const ContactOptions& opt) {
  const int N = db.num_frames, J = db.num_joints;
  const int C = static_cast<int>(db.clip_ranges.size() / 2);
  // Global positions of the two toes and two ankles (N x 4 x 3), one FK per frame.
  const int joints[4] = {db.roles.toe[0], db.roles.toe[1], db.roles.foot[0], db.roles.foot[1]};
  std::vector<float> track(static_cast<size_t>(N) * 4 * 3);
  std::vector<float> gp(static_cast<size_t>(J) * 3), gr(static_cast<size_t>(J) * 4);
  for (int f = 0; f < N; ++f) {
    const size_t o = static_cast<size_t>(f) * J;
    pose_forward_kinematics(db.skeleton.parents, &db.bone_translations[o * 3], &db.bone_rotations[o * 4], gp.data(),
                            gr.data());
    for (int k = 0; k < 4; ++k)
      for (int c = 0; c < 3; ++c) track[(static_cast<size_t>(f) * 4 + k) * 3 + c] = gp[joints[k] * 3 + c];
  }
  // Ground height of each tracked joint: a low percentile of its height.
  float ground[4];
  std::vector<float> h(N);
  for (int k = 0; k < 4; ++k) {
    for (int f = 0; f < N; ++f) h[f] = track[(static_cast<size_t>(f) * 4 + k) * 3 + 1];
    const size_t q = std::min<size_t>(N - 1, static_cast<size_t>(opt.ground_percentile / 100.0f * (N - 1)));
    std::nth_element(h.begin(), h.begin() + q, h.end());
    ground[k] = N ? h[q] : 0.0f;
  }
  std::vector<uint8_t> raw(static_cast<size_t>(N) * 2, 0);
  for (int c = 0; c < C; ++c) {
    const int b = db.clip_ranges[c * 2], e = db.clip_ranges[c * 2 + 1];
    for (int f = b; f < e; ++f) {
      const int f0 = std::max(b, f - 1), f1 = std::min(e - 1, f + 1);
      const float dt = (f1 - f0) / db.fps;
      for (int side = 0; side < 2; ++side) {
        bool planted = false;
        for (int k : {side, side + 2}) {  // toe, then ankle
          const float* p0 = &track[(static_cast<size_t>(f0) * 4 + k) * 3];
          const float* p1 = &track[(static_cast<size_t>(f1) * 4 + k) * 3];
          const float speed = dt > 0 ? std::hypot(p1[0] - p0[0], p1[2] - p0[2]) / dt : 0.0f;
          const float height = track[(static_cast<size_t>(f) * 4 + k) * 3 + 1];
          if (height < ground[k] + opt.height_tolerance && speed < opt.max_speed) planted = true;
        }
        raw[static_cast<size_t>(f) * 2 + side] = planted;
      }
    }
  }
  // Median (majority) filter within each clip.
  db.contacts.assign(static_cast<size_t>(N) * 2, 0);
  const int half = std::max(0, opt.median_window / 2);
  for (int c = 0; c < C; ++c) {
    const int b = db.clip_ranges[c * 2], e = db.clip_ranges[c * 2 + 1];
    for (int f = b; f < e; ++f)
      for (int side = 0; side < 2; ++side) {
        int on = 0, n = 0;
        for (int g = std::max(b, f - half); g <= std::min(e - 1, f + half); ++g, ++n) on += raw[static_cast<size_t>(g) * 2 + side];
        db.contacts[static_cast<size_t>(f) * 2 + side] = (2 * on > n) ? 1 : 0;
      }
  }
}

Database database_build(const std::vector<Motion>& clips, const DatabaseOptions& opt) {
  std::vector<const Motion*> ptrs;
  for (const Motion& m : clips) ptrs.push_back(&m);
  return database_build(ptrs, opt);
}

namespace {

// Every clip must exist and share the first one's skeleton and frame rate.
void check_clips(const std::vector<const Motion*>& clips) {
  if (clips.empty()) throw std::invalid_argument("no clips to build a database from");
  for (const Motion* m : clips)
    if (!m) throw std::invalid_argument("database_build: null clip");
  const Motion& first = *clips.front();
  for (const Motion* mp : clips) {
    const Motion& m = *mp;
    if (!m.skeleton.same_hierarchy(first.skeleton))
      throw std::invalid_argument("'" + m.source + "' has a different skeleton (joint names or hierarchy) than '" +
                                  first.source + "'; a database needs one skeleton");
    if (std::fabs(m.frame_time - first.frame_time) > 1e-4f * first.frame_time + 1e-7f)
      throw std::invalid_argument("'" + m.source + "' has frame time " + std::to_string(m.frame_time) + " but '" +
                                  first.source + "' has " + std::to_string(first.frame_time) +
                                  "; resample the clips to one frame rate");
  }
}

// Root deltas of one clip (F frames): (dx, dz) of frame i -> i + 1 in frame i's character
// frame (meters) and the yaw change (radians); the last frame repeats its predecessor's.
void clip_root_deltas(int F, const float* rp, const float* ry, float* rd) {
  for (int i = 0; i + 1 < F; ++i) {
    const Vec2 d = world_to_local_xz(rp[(i + 1) * 3] - rp[i * 3], rp[(i + 1) * 3 + 2] - rp[i * 3 + 2], ry[i]);
    rd[i * 3] = d.x();
    rd[i * 3 + 1] = d.y();
    rd[i * 3 + 2] = wrap_angle(ry[i + 1] - ry[i]);
  }
  for (int k = 0; k < 3; ++k) rd[(F - 1) * 3 + k] = F > 1 ? rd[(F - 2) * 3 + k] : 0.0f;
}

}  // namespace

Database database_build(const std::vector<const Motion*>& clips_in, const DatabaseOptions& opt) {
  check_clips(clips_in);
  const Motion& first = *clips_in.front();
  Database db;
  db.skeleton = first.skeleton;
  db.roles = skeleton_find_roles(db.skeleton, opt.roles);
  db.fps = first.fps();
  db.source_scale = first.scale;
  db.num_joints = db.skeleton.num_joints();
  db.normalization.weights = opt.weights;

  std::vector<const Motion*> clips;
  std::vector<Motion> mirrored;
  for (const Motion* m : clips_in) clips.push_back(m);
  if (opt.mirror) {
    const auto map = skeleton_mirror_map(db.skeleton, db.roles);  // the legs pair by role, overrides included
    const auto corrections = mirror_corrections(clips_in, map);  // one set for every clip of the skeleton
    mirrored.reserve(clips_in.size());
    for (const Motion* m : clips_in) mirrored.push_back(motion_mirror(*m, map, corrections));
    for (const Motion& m : mirrored) clips.push_back(&m);
  }

  size_t N = 0;
  for (const Motion* m : clips) N += m->num_frames;
  if (N > static_cast<size_t>(INT32_MAX)) throw std::invalid_argument("too many frames");
  const int J = db.num_joints;
  db.num_frames = static_cast<int>(N);
  db.bone_translations = std::vector<float>(N * J * 3);
  db.bone_rotations = std::vector<float>(N * J * 4);
  db.root_positions = std::vector<float>(N * 3);
  db.root_yaws = std::vector<float>(N);
  db.root_deltas = std::vector<float>(N * 3);
  db.features = std::vector<float>(N * kFeatureDim);
  float* translations = db.bone_translations.mutable_data();
  float* rotations = db.bone_rotations.mutable_data();

  const JointRoles& r = db.roles;
  size_t start = 0;
  std::vector<float> gp;
  std::vector<float> hips, lul, rul, lf, rf;
  for (size_t c = 0; c < clips.size(); ++c) {
    const Motion& m = *clips[c];
    const int F = m.num_frames;
    std::copy(m.translations.begin(), m.translations.end(), translations + start * J * 3);
    std::copy(m.rotations.begin(), m.rotations.end(), rotations + start * J * 4);
    gp.resize(static_cast<size_t>(F) * J * 3);
    motion_forward_kinematics(m, gp.data(), nullptr);
    auto track = [&](int joint, std::vector<float>& out) {
      out.resize(static_cast<size_t>(F) * 3);
      for (int f = 0; f < F; ++f)
        for (int k = 0; k < 3; ++k) out[f * 3 + k] = gp[(static_cast<size_t>(f) * J + joint) * 3 + k];
    };
    track(r.hips, hips);
    track(r.upper_leg[0], lul);
    track(r.upper_leg[1], rul);
    track(r.foot[0], lf);
    track(r.foot[1], rf);
    float* rp = db.root_positions.mutable_data() + start * 3;
    float* ry = db.root_yaws.mutable_data() + start;
    clip_character_frames(F, db.fps, hips.data(), lul.data(), rul.data(), rp, ry);
    clip_features(F, db.fps, lf.data(), rf.data(), hips.data(), rp, ry, db.features.mutable_data() + start * kFeatureDim);
    clip_root_deltas(F, rp, ry, db.root_deltas.mutable_data() + start * 3);
    db.clip_ranges.push_back(static_cast<int32_t>(start));
    db.clip_ranges.push_back(static_cast<int32_t>(start + F));
    db.clip_names.push_back(m.source);
    db.clip_mirrored.push_back(c >= clips_in.size() ? 1 : 0);
    start += F;
  }
  db.index_clips();
  db.refit_normalization();
  database_compute_contacts(db);
  return db;
}

}  // namespace mmrl
