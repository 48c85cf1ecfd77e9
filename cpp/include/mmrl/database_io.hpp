// The saved form of a Database: the arrays of mmrl's database file (version 2 of the .npz
// that python/mmrl/motion/database.py writes atomically and reads without pickles), and the rules
// that turn them back into a Database. The Python layer owns the file; this owns the format's
// meaning: shapes, the skeleton's channel text, the role layout, the derived arrays.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "mmrl/buffer.hpp"
#include "mmrl/database.hpp"

namespace mmrl {

// A stored array: values in C order and the shape they had in the file. The values may be
// borrowed (Buffer::borrow): a database built from borrowed arrays keeps borrowing its large
// per-frame arrays instead of copying them.
template <class T>
struct StateArray {
  Buffer<T> values;
  std::vector<int64_t> shape;
};

// Every field of the file but its "format" and "version" (N frames, J joints, C clips).
struct DatabaseState {
  std::vector<std::string> joint_names;  // J
  StateArray<int32_t> parents;           // J, -1 for the root, each parent before its child
  StateArray<float> offsets;             // J x 3, meters
  StateArray<float> end_sites;           // J x 3, meters
  StateArray<uint8_t> has_end_site;      // J
  std::vector<std::string> channels;     // J, see skeleton_channels_text
  std::vector<int> roles;                // 9 joint indices in joint_role_names() order
  float fps = 0;
  float source_scale = 1;
  std::vector<std::string> clip_names;   // C
  StateArray<int32_t> clip_ranges;       // C x 2, [start, stop), contiguous from 0 to N
  StateArray<uint8_t> clip_mirrored;     // C
  std::vector<std::string> tag_names;    // T, optional (tags.hpp)
  StateArray<uint8_t> clip_tags;         // C x T, optional (empty with no tag names)
  StateArray<float> bone_translations;   // N x J x 3
  StateArray<float> bone_rotations;      // N x J x 4 (w, x, y, z)
  StateArray<float> root_positions;      // N x 3
  StateArray<float> root_yaws;           // N
  StateArray<float> root_deltas;         // N x 3
  StateArray<float> features;            // N x 27, raw units
  StateArray<uint8_t> contacts;          // N x 2
  StateArray<float> feature_mean;        // 27
  StateArray<float> block_scale;         // 5
  StateArray<float> weights;             // 5
  // Optional (empty: derived from the features): N x 27, the normalized features. When given,
  // they must equal what the normalization computes, bit for bit; a borrowed array is then
  // kept as the database's own instead of a derived copy.
  StateArray<float> normalized;
};

// A joint's channels as text: BVH channel names separated by single spaces, in file order
// ("Xposition Yposition Zposition Zrotation Xrotation Yrotation"; "" for no channels).
std::vector<std::string> skeleton_channels_text(const Skeleton& skeleton);
// The inverse for one joint. Throws std::invalid_argument on an unknown name.
std::vector<Channel> channels_from_text(const std::string& text);

// Rebuilds a Database from its saved arrays: checks every shape against (N, J, C), the
// hierarchy, the channels and the roles, then validates the arrays and derives the valid
// mask, the frame -> clip index and the normalized features. Throws std::invalid_argument
// naming the field ("database state: 'features' has shape ...").
Database database_from_state(DatabaseState state);

}  // namespace mmrl
