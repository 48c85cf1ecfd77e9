// The motion database: clips concatenated into flat per-frame arrays (Holden style).
//
// Offline code: database_build parses nothing itself; it takes parsed Motions, finds the
// joint roles, optionally adds mirrored copies, and computes character frames, features,
// root deltas, the valid-match mask and the normalisation.
#pragma once

#include <array>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "mmrl/buffer.hpp"
#include "mmrl/bvh.hpp"
#include "mmrl/features.hpp"
#include "mmrl/skeleton.hpp"

namespace mmrl {

struct DatabaseOptions {
  // Add a left/right mirrored copy of every clip (after all originals, in the same order). The
  // legs pair by their roles (overrides included), the other joints by name (skeleton_mirror_map).
  bool mirror = false;
  // Role name -> joint name, overriding detection (see skeleton.hpp).
  std::map<std::string, std::string> roles;
  // Block weights in feature_blocks() order.
  std::array<float, kNumBlocks> weights = {0.75f, 1.0f, 1.0f, 1.0f, 1.5f};
};

// Frames ahead at which Database::path_samples records where the frames played from a frame
// take the root: every second frame of a default step (6 frames), then every 5 frames up to
// the trajectory's last horizon (a valid frame has that many frames left in its clip). The
// collision-aware search (tasks/path_filter.hpp) tests a candidate's path at these times.
constexpr int kPathSamples = 9;
constexpr int kPathSampleFrames[kPathSamples] = {2, 4, 6, 8, 10, 15, 20, 25, 30};

struct Database {
  // Skeleton shared by all clips.
  Skeleton skeleton;
  JointRoles roles;
  float fps = 30.0f;
  float source_scale = 1.0f;  // file units -> meters of the source BVH (for export)
  int num_frames = 0;
  int num_joints = 0;

  // Clips: [start, stop) frame ranges in database order, their source names and whether
  // they are mirrored copies.
  std::vector<int32_t> clip_ranges;  // C x 2
  std::vector<std::string> clip_names;
  std::vector<uint8_t> clip_mirrored;
  // Tags on clips (tags.hpp): T names "group=value" and a C x T matrix, 1 where clip c carries
  // tag t. No names: an untagged database. A mirrored clip carries its original's tags.
  std::vector<std::string> tag_names;
  std::vector<uint8_t> clip_tags;

  // The per-frame float arrays are Buffers: owned after building or loading a file, or
  // borrowed from memory shared between processes (mmrl.integrations.rllib).
  // Per-frame local pose (meters; quaternions w x y z), N x J x 3 and N x J x 4.
  Buffer<float> bone_translations;
  Buffer<float> bone_rotations;

  // Character frame in world space: root positions (N x 3, y = 0) and yaws (N, radians).
  Buffer<float> root_positions;
  Buffer<float> root_yaws;
  // Root motion from frame i to i + 1 in frame i's character frame: (dx, dz, dyaw) (N x 3).
  // The last frame of a clip repeats the previous delta.
  Buffer<float> root_deltas;

  Buffer<float> features;    // N x 27, raw units
  Buffer<float> normalized;  // N x 27, (f - mean) / column_scale
  FeatureNormalization normalization;
  // 1 where frame i + 30 stays inside frame i's clip: the frames a search may return.
  std::vector<uint8_t> valid;
  // Per frame, the clip index.
  std::vector<int32_t> frame_clip;
  // The frames with valid[i] set, ascending (episode starts are drawn from them).
  std::vector<int64_t> valid_frames;
  // Per frame i, the root's (x, z) in frame i's character frame kPathSampleFrames[s] frames
  // later, for valid frames (N x kPathSamples x 2, meters; 0 for frames that are not valid):
  // the path that playing from i takes. Derived from the character frames by index_clips.
  std::vector<float> path_samples;
  // Per sample s, the largest distance (meters) of path_samples[.][s] from the root.
  std::array<float, kPathSamples> path_reach{};
  // Foot contacts (N x 2: left, right; 1 = planted), see database_compute_contacts.
  std::vector<uint8_t> contacts;

  int num_clips() const { return static_cast<int>(clip_names.size()); }

  // Recomputes `normalized` for new block weights (the mean and block scales stay).
  void set_weights(const std::array<float, kNumBlocks>& weights);
  // std::invalid_argument unless every block weight is positive and finite.
  static void check_weights(const std::array<float, kNumBlocks>& weights);
  // Recomputes normalization (mean, block scales) from the features and current weights.
  void refit_normalization();
  // Fills the derived per-frame arrays (valid, frame_clip, valid_frames, path_samples,
  // path_reach) from clip_ranges and the character frames. Called by build and after loading.
  void index_clips();
  // Throws std::invalid_argument if array sizes disagree or values are not finite.
  void validate() const;
};

// Mirroring across the world YZ plane (x -> -x), swapping left and right joints, in the
// skeleton's own joint bases: a mirrored clip keeps the skeleton's bone offsets, and its local
// rotations mean what the original clips' mean, so a blend between an original clip and a
// mirrored one (a transition) moves between two poses of the same skeleton.
//
// Joint j's global rotation in the mirror is M G_s(j) M C_j (M the reflection, s(j) the
// mirror partner, G the source's global rotation) with one constant correction C_j per joint
// and skeleton (mirror_corrections): the rotation that takes j's child offsets (and end site)
// to its partner's mirrored ones (a best fit when j has two or more, which is exact for a
// skeleton whose sides mirror each other), or for a joint with one child or none, the mean
// of the rotation that maps the partner's mirrored pose onto j's over the clips' frames (then
// turned to fit the child exactly), which near-symmetric locomotion averages to the rest
// symmetry. A root joint with fewer than two fixed children keeps C = identity (its rotation
// carries the heading, which the mirror must flip). Joints that translate (roots, and joints
// whose translation leaves its offset on some frame) are placed at the mirrored positions
// exactly; the others keep their offsets.
//
// Without it (C = identity and every translation recomputed from the mirrored positions, as
// before) a skeleton whose rest pose is not mirror-symmetric in world X (Bandai-Namco's
// bones lie along their local X) gets mirrored clips in other joint bases: the hips' local
// rotation differed by 180 degrees, and every transition between an original and a mirrored
// clip jumped (joystick foot sliding 131 cm/s on the mirrored shared data, against 19).
std::vector<Quat> mirror_corrections(const std::vector<const Motion*>& clips, const std::vector<int>& mirror_map);
Motion motion_mirror(const Motion& motion, const std::vector<int>& mirror_map, const std::vector<Quat>& corrections);
// The same with the corrections of this motion alone.
Motion motion_mirror(const Motion& motion, const std::vector<int>& mirror_map);

// Foot contact detection (offline). A foot is planted on a frame when its toe or its ankle
// is near the ground and slow: height below ground + height_tolerance and horizontal speed
// below max_speed. The ground heights of the toe and the ankle are estimated per side as
// the ground_percentile-th percentile of their heights over the whole database (Bandai:
// toes rest at about 4 cm, ankles at about 12 cm). The flags are then median-filtered over
// median_window frames within each clip, which removes single-frame flickers.
struct ContactOptions {
  float max_speed = 0.15f;         // m/s, horizontal, central differences
  float height_tolerance = 0.03f;  // meters above the estimated ground height
  float ground_percentile = 5.0f;  // percent
  int median_window = 5;           // frames (odd)
};

// Fills db.contacts (N x 2) from the local pose arrays. Needs roles and clip ranges.
void database_compute_contacts(Database& db, const ContactOptions& options = {});

Database database_build(const std::vector<const Motion*>& clips, const DatabaseOptions& options = {});
Database database_build(const std::vector<Motion>& clips, const DatabaseOptions& options = {});

}  // namespace mmrl
