// A small procedural database for the env tests: a 9-joint biped (hips, and per side upper
// leg, lower leg, foot, toe, named so skeleton_find_roles finds them) walking along arcs.
// Each clip has its own speed (m/s) and turn rate (rad/s); the legs swing with the gait, so
// pose features differ between clips and along them. No file and no real mocap involved.
#pragma once

#include <cmath>
#include <string>
#include <vector>

#include "mmrl/database.hpp"
#include "mmrl/search.hpp"

namespace mmrl {
namespace testing_db {

inline Motion walk_clip(float speed, float turn_rate, int frames, float phase0) {
  Motion m;
  Skeleton& sk = m.skeleton;
  const char* names[9] = {"Hips",     "LeftUpLeg",  "LeftLeg",  "LeftFoot", "LeftToeBase",
                          "RightUpLeg", "RightLeg", "RightFoot", "RightToeBase"};
  const int parents[9] = {-1, 0, 1, 2, 3, 0, 5, 6, 7};
  // Meters, parent frame; +X is the character's left, +Z forward at yaw 0.
  const float offsets[9][3] = {{0, 0, 0},      {0.1f, -0.05f, 0},  {0, -0.42f, 0}, {0, -0.42f, 0}, {0, -0.05f, 0.12f},
                               {-0.1f, -0.05f, 0}, {0, -0.42f, 0}, {0, -0.42f, 0}, {0, -0.05f, 0.12f}};
  for (int j = 0; j < 9; ++j) {
    sk.names.push_back(names[j]);
    sk.parents.push_back(parents[j]);
    sk.offsets.emplace_back(offsets[j][0], offsets[j][1], offsets[j][2]);
    sk.has_end_site.push_back(j == 4 || j == 8);
    sk.end_sites.emplace_back(0, 0, (j == 4 || j == 8) ? 0.05f : 0);
    if (j == 0)
      sk.channels.push_back({Channel::Xposition, Channel::Yposition, Channel::Zposition, Channel::Yrotation,
                             Channel::Xrotation, Channel::Zrotation});
    else
      sk.channels.push_back({Channel::Zrotation, Channel::Yrotation, Channel::Xrotation});
  }
  m.source = "synthetic";
  m.frame_time = 1.0f / 30.0f;
  m.scale = 1.0f;
  m.num_frames = frames;
  m.translations.resize(static_cast<size_t>(frames) * 9 * 3);
  m.rotations.resize(static_cast<size_t>(frames) * 9 * 4);
  double x = 0, z = 0, yaw = 0;
  const double dt = 1.0 / 30.0, stride_hz = 0.8 + 0.4 * speed;
  for (int f = 0; f < frames; ++f) {
    const double phase = phase0 + 6.283185307179586 * stride_hz * f * dt;
    float* tr = &m.translations[static_cast<size_t>(f) * 27];
    float* rot = &m.rotations[static_cast<size_t>(f) * 36];
    for (int j = 0; j < 9; ++j) {
      tr[j * 3] = offsets[j][0], tr[j * 3 + 1] = offsets[j][1], tr[j * 3 + 2] = offsets[j][2];
      quat_store(Quat::Identity(), &rot[j * 4]);
    }
    tr[0] = static_cast<float>(x);
    tr[1] = 0.95f + 0.02f * static_cast<float>(std::cos(2 * phase));
    tr[2] = static_cast<float>(z);
    quat_store(quat_from_yaw(static_cast<float>(yaw)), &rot[0]);
    const float swing = static_cast<float>(0.25 + 0.1 * speed) * static_cast<float>(std::sin(phase));
    const Vec3 ax = Vec3::UnitX();
    quat_store(Quat(Eigen::AngleAxisf(-swing, ax)), &rot[1 * 4]);
    quat_store(Quat(Eigen::AngleAxisf(swing, ax)), &rot[5 * 4]);
    quat_store(Quat(Eigen::AngleAxisf(0.3f + 0.3f * std::max(0.0f, swing), ax)), &rot[2 * 4]);
    quat_store(Quat(Eigen::AngleAxisf(0.3f + 0.3f * std::max(0.0f, -swing), ax)), &rot[6 * 4]);
    // Advance the root along the arc (forward = (sin yaw, cos yaw)).
    x += speed * std::sin(yaw) * dt;
    z += speed * std::cos(yaw) * dt;
    yaw += turn_rate * dt;
  }
  return m;
}

// 12 clips of 4 s at 30 fps: speeds 0.3 .. 2.5 m/s, turns left, right and straight.
inline const Database& database() {
  static const Database db = [] {
    std::vector<Motion> clips;
    const float speeds[4] = {0.3f, 1.0f, 1.6f, 2.5f};
    const float turns[3] = {0.0f, 0.6f, -0.9f};
    int k = 0;
    for (float v : speeds)
      for (float w : turns) clips.push_back(walk_clip(v, w, 120, 0.7f * static_cast<float>(k++)));
    return database_build(clips);
  }();
  return db;
}

inline const Matcher& matcher() {
  static const Matcher m(database().normalized.data(), database().num_frames, kFeatureDim, database().valid.data());
  return m;
}

}  // namespace testing_db
}  // namespace mmrl
