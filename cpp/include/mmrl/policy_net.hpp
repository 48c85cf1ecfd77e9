// A trained policy evaluated in C++ (no torch): the exported network's deterministic action.
//
//   action = action_center + action_half * net(clamp(obs * obs_scale + obs_shift, -clip, clip))
//
// which is mmrl.load_policy(...).act(obs) (python/mmrl/rl/trained_policy.py). Two networks:
//   - kMlp: dense layers with an activation after each (PlaneActorCritic's actor: 32 x 32 tanh);
//   - kConvTower: ObstacleActorCritic's actor: the observation's map segment (C x H x W, C order)
//     through convolutions (stride 1, no padding, each with its activation), flattened in
//     (channel, row, col) order, then dense layer 0 (the map's FC); its output is concatenated
//     with the observation's vector segment and runs through the remaining dense layers.
// Weights are float32 as trained: dense (out x in, row-major), conv (out x in x kh x kw) in the
// file; in memory each layer keeps them transposed (in x out, each row padded to whole 8-float
// lanes), so a layer adds weight rows for its non-zero inputs only: ReLU outputs and the binary
// sensor maps are mostly zeros. act() allocates nothing: every intermediate lives in a PolicyScratch the caller owns (one
// per character, or per thread), so many characters share one PolicyNet.
#pragma once

#include <cstdint>
#include <vector>

#include "mmrl/runtime_file.hpp"

namespace mmrl {

enum class Activation : int32_t { kNone = 0, kTanh = 1, kRelu = 2 };

// A layer's weights as its kernel reads them: in x stride floats, row i the weights of input i
// for every output (stride: out rounded up to whole lanes, the padding zero).
struct TransposedWeights {
  int stride = 0;
  std::vector<float> rows;
  void assign(const std::vector<float>& weight, int out, int in);  // weight: out x in, row-major
};

struct DenseLayer {
  int in = 0, out = 0;
  TransposedWeights weight;  // in x out
  std::vector<float> bias;   // out
  Activation activation = Activation::kNone;
};

struct ConvLayer {
  int in_channels = 0, out_channels = 0, kernel_h = 0, kernel_w = 0;
  int in_h = 0, in_w = 0;    // input size (the output is in - kernel + 1)
  TransposedWeights weight;  // (in x kh x kw) x out
  std::vector<float> bias;   // out
  Activation activation = Activation::kNone;
};

struct PolicyScratch {
  std::vector<float> a, b;         // ping-pong buffers, sized for the widest layer
  std::vector<float> sums;         // a convolution's sums (positions x padded outputs)
  std::vector<int32_t> index;      // a layer's non-zero inputs: their indices
  std::vector<float> value;        // ... and values
};

class PolicyNet {
 public:
  enum Kind : int32_t { kMlp = 1, kConvTower = 2 };

  // Reads the policy sections of a checked controller file (docs/runtime.md); every shape is
  // checked against the header, errors name the file and section.
  static PolicyNet from_file(const ControllerFile& file);

  int obs_dim() const { return obs_dim_; }
  int act_dim() const { return act_dim_; }
  Kind kind() const { return kind_; }
  PolicyScratch make_scratch() const;
  // obs: obs_dim floats; action: act_dim floats.
  void act(const float* obs, float* action, PolicyScratch& scratch) const;
  size_t num_parameters() const;

 private:
  void read_layers(const ControllerFile& file, const std::vector<int32_t>& header);
  Kind kind_ = kMlp;
  int obs_dim_ = 0, act_dim_ = 0;
  int map_start_ = 0, map_c_ = 0, map_h_ = 0, map_w_ = 0, vector_start_ = 0, vector_size_ = 0;
  std::vector<ConvLayer> convs_;
  std::vector<DenseLayer> dense_;
  std::vector<float> obs_scale_, obs_shift_, action_center_, action_half_;
  float obs_clip_ = 10.0f;
};

}  // namespace mmrl
