// A compressed controller: learned motion matching (Holden, Kanoun, Perepichka, Popa 2020;
// docs/compressed.md). Three small networks stand in for the database:
//   - the decompressor, from a state [X, Zn] (X: a frame's 27 normalized matching features,
//     Zn: its latent, normalized) to that frame's pose row (python/mmrl/compress/pose.py);
//   - the stepper, which advances a state by one frame (playback): s' = s + stepper(s);
//   - the projector, from a query (27, normalized) to the state of its best match (the search).
//
// The decision (compressed_decision) keeps the database's continuation rule: the state played
// now is the starting best, and the projection replaces it only when it is closer to the query
// by more than the transition cost (squared normalized distance between the query and a
// state's X; the same cost a database match reports). A transition is an accepted projection.
//
// Pose rows (9 J + 5 floats): J x 6 rotations (the first two columns of each joint's local
// rotation matrix, row-major; a root joint's relative to the character frame's yaw), J x 3
// translations (a root joint's in the character frame), the root delta to the next frame
// (dx, dz, dyaw in this frame's character frame) and the two foot contacts (> 0.5: planted).
//
// Evaluation allocates nothing: every intermediate lives in a CompressedScratch the caller owns.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "mmrl/features.hpp"
#include "mmrl/kdtree.hpp"
#include "mmrl/math.hpp"

namespace mmrl {

constexpr int kMlpMaxRows = 8;            // rows a network evaluates together (Mlp::forward)
constexpr int kCompressedMaxFrames = 30;  // frames one playback may decode (decision.hpp's kMaxFramesPerStep)

// A dense network: layers out x in (row-major) with biases, ELU between layers, none after the last.
// forward runs the weights as packed by pack(): IEEE float16 (rounded to nearest even), in
// blocks of 8 outputs, input-major (one load per input feeds 8 outputs), widened to float32 and
// summed in float32 in the library's 8-lane vectors, compiled for x86-64 with F16C (Haswell on)
// and the baseline; every output sums its inputs in order, so the clones agree bit for bit.
// float16 halves the bytes a frame streams through the cache (the networks are read by every
// character every frame) at a relative weight error of at most 2^-11 for |w| >= 2^-14 (an
// absolute one of at most 2^-25 below, where float16 is subnormal; docs/compressed.md).
struct Mlp {
  struct Layer {
    int in = 0, out = 0;
    std::vector<float> weight, bias;  // weight: released by pack() (the packed copy is what runs)
    std::vector<uint16_t> packed;     // pack(): ceil(out / 8) blocks of in x 8 float16 bits, zero-padded
  };
  std::vector<Layer> layers;

  // Packs every layer's weights for forward and releases the float32 weights; a packed layer
  // stays packed. check()s first, so a network that does not fit (a weight beyond float16's
  // range, 65504, included) throws std::invalid_argument and stays as it was.
  void pack();
  int input_dim() const { return layers.empty() ? 0 : layers.front().in; }
  int output_dim() const { return layers.empty() ? 0 : layers.back().out; }
  int max_width() const;
  size_t num_parameters() const;
  size_t memory_bytes() const;  // the weights as held (float32 or packed) and the biases
  // Throws std::invalid_argument (naming `what`) unless the layers chain and every array has its
  // size (a packed layer's: its packed weights).
  void check(const std::string& what) const;
  // out = net(in) for `rows` rows (1..kMlpMaxRows; in: rows x input_dim, out: rows x
  // output_dim), pack() first; scratch: 2 * kMlpMaxRows * max_width() floats (not aliasing in or
  // out). A row's result is the same bit for bit whatever the number of rows.
  void forward(const float* in, float* out, float* scratch, int rows = 1) const;
};

// The float32 value of IEEE float16 bits (exact; infinities and NaNs too, which check() refuses).
float float16_to_float(uint16_t bits);

// The dense kernel this process runs: "f16c" (AVX2 and F16C) or "widening" (any CPU; the same bits).
const char* mlp_kernel();

struct CompressedScratch {
  std::vector<float> a, b, state, pose_input;
};

class CompressedModel {
 public:
  int num_joints = 0;
  int latent = 0;
  Mlp decompressor, stepper, projector;
  std::vector<float> y_mean, y_std;  // pose_dim: decompressor output * y_std + y_mean = pose row
  std::vector<float> z_mean, z_std;  // latent: Z = Zn * z_std + z_mean
  // Joints whose local translation never changes in the database (a bone's length): decode
  // writes fixed_translations (J x 3) for them instead of the network's estimate, so bones keep
  // their lengths. Empty: every translation is decoded.
  std::vector<uint8_t> fixed_joints;
  std::vector<float> fixed_translations;

  int pose_dim() const { return 9 * num_joints + 5; }
  int state_dim() const { return kFeatureDim + latent; }
  // Throws std::invalid_argument naming what does not fit (sizes of the networks and arrays).
  void check() const;
  // check(), then packs the three networks: what a model needs before it runs.
  void prepare();
  // True once prepare() has packed the networks.
  bool prepared() const;
  CompressedScratch make_scratch() const;
  size_t num_parameters() const;
  size_t memory_bytes() const;

  // The pose row (pose_dim) of a state; decode_rows: of `rows` states (rows x state_dim ->
  // rows x pose_dim), evaluated kMlpMaxRows at a time, each row equal to its decode().
  void decode(const float* state, float* pose, CompressedScratch& scratch) const;
  void decode_rows(const float* states, float* poses, int rows, CompressedScratch& scratch) const;
  // Advances a state by one frame, in place.
  void step(float* state, CompressedScratch& scratch) const;
  // The state (state_dim) of a query's best match.
  void project(const float* query, float* state, CompressedScratch& scratch) const;
};

// Squared distance between a query and a state's features (27 normalized floats each).
inline float feature_distance(const float* query, const float* state) {
  float d = 0;
  for (int k = 0; k < kFeatureDim; ++k) d += (query[k] - state[k]) * (query[k] - state[k]);
  return d;
}

// The compressed decision (see the header comment): projects the query into `projected`
// (state_dim floats) and returns true when it replaces `current`; cost: the chosen state's.
bool compressed_decision(const CompressedModel& model, const float* current, const float* query,
                         float transition_cost, float* projected, float* cost, CompressedScratch& scratch);
// The same rule with a candidate filter (kdtree.hpp's CandidateFilter, each candidate a state
// without a row: the obstacles task's collision-aware search prices it) over several projections:
// queries holds n rows (1..kMlpMaxRows, projected together), the first the query itself and
// the others its turned copies (decision.hpp's shortlist_queries). Every candidate (the
// continuation and each projection) costs its squared distance to the first query plus the
// filter's price; the cheapest projection replaces the continuation when it is cheaper by more
// than the transition cost, as a database match does. When the filter refuses every candidate
// the decision is made again with its fallback, down to no filter. filter null and n = 1: the
// rule above, bit for bit.
bool compressed_decision(const CompressedModel& model, const float* current, const float* queries, int n,
                         float transition_cost, const CandidateFilter* filter, float* projected, float* cost,
                         CompressedScratch& scratch);

// Playback of a chosen state: rows (frames + 1) x pose_dim, row k the pose of the k-th frame
// from `start` (row 0: start itself); `end` (may alias start) gets the state after `frames`
// steps (0 <= frames <= kCompressedMaxFrames). The states are stepped first, then decoded together.
void compressed_playback(const CompressedModel& model, const float* start, int frames, float* rows, float* end,
                         CompressedScratch& scratch);

// A pose row's rotation block (6 floats) as a unit quaternion (Gram-Schmidt, as in training).
Quat rotation_from_6d(const float* six);

}  // namespace mmrl
