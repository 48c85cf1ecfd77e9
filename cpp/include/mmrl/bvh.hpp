// BVH text -> Motion (skeleton + per-frame local transforms), and Motion -> BVH text.
//
// Any channel layout is accepted: 0 to 6 channels per joint, position and rotation
// channels in any order, End Sites, any frame time, tabs, CRLF and blank lines. A joint's
// name is the rest of the line after ROOT/JOINT, trimmed, so it may hold spaces ("Bip01 L
// Thigh"); bvh_write writes it back the same way.
// Position channels *replace* the matching component of the joint's OFFSET (they are not
// added to it). Rotation channels listed as "Zrotation Xrotation Yrotation" give the local
// rotation Rz * Rx * Ry (intrinsic, in listed order), in degrees.
//
// Units: everything inside a Motion is in meters, Y up. The scale from file units to meters is
// either given (> 0) or inferred (see bvh_infer_scale). A file whose world is Z up is rotated
// to Y up at import (given, or detected from the hips and feet; see motion_import.hpp), and
// a clip can be resampled to another frame rate at import (positions linear, rotations slerp).
#pragma once

#include <array>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "mmrl/math.hpp"

namespace mmrl {

// A malformed BVH file. what() reads "<file>:<line>: <message>".
class BVHError : public std::runtime_error {
 public:
  BVHError(const std::string& file, int line, const std::string& message)
      : std::runtime_error(file + ":" + std::to_string(line) + ": " + message), file_(file), line_(line) {}
  const std::string& file() const { return file_; }
  int line() const { return line_; }

 private:
  std::string file_;
  int line_;
};

enum class Channel : int8_t { Xposition = 0, Yposition, Zposition, Xrotation, Yrotation, Zrotation };

// The world's up axis in a file. Auto: detect it (motion_detect_up_axis).
enum class UpAxis : int8_t { Auto = 0, Y, Z };

struct BVHImportOptions {
  float scale = 0.0f;         // file units -> meters; <= 0 infers it (bvh_infer_scale)
  UpAxis up = UpAxis::Auto;   // the file's up axis; Z rotates the world to Y up
  float fps = 0.0f;           // resample to this rate (frames per second); <= 0 keeps the file's
};

struct Skeleton {
  std::vector<std::string> names;
  std::vector<int> parents;                  // -1 for a root
  std::vector<Vec3> offsets;                 // meters, in the parent's frame
  std::vector<uint8_t> has_end_site;         // 1 if the joint ends in an End Site
  std::vector<Vec3> end_sites;               // meters, End Site offset (zero if none)
  std::vector<std::vector<Channel>> channels;  // per joint, in file order

  int num_joints() const { return static_cast<int>(names.size()); }
  int num_channels() const;
  int find(const std::string& name) const;  // -1 if absent
  bool same_hierarchy(const Skeleton& other) const;
};

struct Motion {
  Skeleton skeleton;
  std::string source;       // file name, for messages
  float frame_time = 0.0f;  // seconds
  float scale = 1.0f;       // file units -> meters, as applied
  float source_fps = 0.0f;  // the file's frame rate, before any resampling
  UpAxis source_up = UpAxis::Y;  // the file's up axis (Z: rotated to Y up at import)
  int num_frames = 0;
  // Local transforms, frames x joints, row-major. Translations in meters; rotations as
  // unit quaternions stored (w, x, y, z).
  std::vector<float> translations;  // F * J * 3
  std::vector<float> rotations;     // F * J * 4

  float fps() const { return frame_time > 0 ? 1.0f / frame_time : 0.0f; }
};

// Parses BVH text. `source` names the file in error messages. Steps after parsing, in order:
// the up axis (detected or given; Z up is rotated to Y up), the scale (inferred when not
// given, on the Y-up skeleton), then resampling to options.fps if it differs from the file's
// rate by more than 1e-4 relative. Throws std::invalid_argument for a negative or non-finite
// options.fps or scale.
Motion bvh_parse(const std::string& text, const std::string& source, const BVHImportOptions& options);
inline Motion bvh_parse(const std::string& text, const std::string& source, float scale = 0.0f) {
  BVHImportOptions options;
  options.scale = scale;
  return bvh_parse(text, source, options);
}

// Reads and parses a file. Throws BVHError (line 0 when the file cannot be read).
Motion bvh_load(const std::string& path, const BVHImportOptions& options);
inline Motion bvh_load(const std::string& path, float scale = 0.0f) {
  BVHImportOptions options;
  options.scale = scale;
  return bvh_load(path, options);
}

// The unit rule (on a Y-up motion): the skeleton's height h in file units is the highest joint
// or End Site in the first frame, measured from the floor y = 0 (or from the lowest point if that is below
// the floor). The scale is the one of {1 (m), 0.01 (cm),
// 0.0254 (inch), 0.001 (mm)} that brings h closest to 1.5 m on a log scale.
float bvh_infer_scale(const Motion& motion_in_file_units);

// Writes a Motion as BVH text on its own skeleton; positions are written in file units
// (divided by motion.scale). Rotation channels are written in each joint's own order.
std::string bvh_write(const Motion& motion);

// Forward kinematics of frames [0, F): global positions (F*J*3, meters) and global
// rotations (F*J*4, w x y z). Either output may be null.
void motion_forward_kinematics(const Motion& motion, float* global_positions, float* global_rotations);

// Forward kinematics of one pose given local translations (J*3) and rotations (J*4, wxyz).
// Parents must precede children (BVH order guarantees it).
void pose_forward_kinematics(const std::vector<int>& parents, const float* local_translations,
                             const float* local_rotations, float* global_positions, float* global_rotations);

// Quaternion helpers for the (w, x, y, z) storage order.
inline Quat quat_load(const float* q) { return Quat(q[0], q[1], q[2], q[3]); }
inline void quat_store(const Quat& q, float* out) {
  out[0] = q.w();
  out[1] = q.x();
  out[2] = q.y();
  out[3] = q.z();
}

}  // namespace mmrl
