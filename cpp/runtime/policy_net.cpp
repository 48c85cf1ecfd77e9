#include "mmrl/policy_net.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "mmrl/simd.hpp"

namespace mmrl {

namespace {

// Calls f with the activation as a function object, so that a loop over a layer's outputs
// branches once, not per output (a per-output switch cost a crowd about 8% of its time).
template <class F>
void with_activation(Activation a, F&& f) {
  switch (a) {
    case Activation::kTanh: return f([](float x) { return std::tanh(x); });
    case Activation::kRelu: return f([](float x) { return x > 0.0f ? x : 0.0f; });
    default: return f([](float x) { return x; });
  }
}

// y[0..stride) = the sum over the non-zero inputs (index[t], value[t]), t ascending with the
// index, of value * row index of w, 8 outputs per lane, up to 32 outputs per pass over the
// inputs (the accumulators stay in registers). The terms are summed in runs of 64, each run's
// sum added to the total: a fixed order (the same bits in every clone), with the rounding
// error of a blocked sum rather than one long running sum (a dense layer can take thousands
// of inputs). A zero input's term is +-0 and changes no sum, so it is skipped: ReLU outputs and
// the binary sensor maps are mostly zeros (a trained obstacles policy: 68% of the maps' cells,
// 54% and 89% of the two convolutions' outputs), so most weight rows are never read.
MMRL_MULTIVERSION void sparse_input_product(const TransposedWeights& w, const int32_t* index, const float* value,
                                            int count, float* y) {
  constexpr int kRun = 64;
  const int stride = w.stride;
  for (int c0 = 0; c0 < stride; c0 += 4 * kLanes) {
    with_count_1_to_8(std::min(4, (stride - c0) / kLanes), [&](auto lanes) {
      constexpr int G = decltype(lanes)::value;
      Lanes total[G];
      for (int g = 0; g < G; ++g) total[g] = Lanes{};
      for (int t0 = 0; t0 < count; t0 += kRun) {
        Lanes run[G];
        for (int g = 0; g < G; ++g) run[g] = Lanes{};
        const int t1 = std::min(count, t0 + kRun);
        for (int t = t0; t < t1; ++t) {
          const float* row = w.rows.data() + static_cast<size_t>(index[t]) * stride + c0;
          for (int g = 0; g < G; ++g) run[g] += value[t] * load_lanes(row + g * kLanes);
        }
        for (int g = 0; g < G; ++g) total[g] += run[g];
      }
      for (int g = 0; g < G; ++g) store_lanes(y + c0 + g * kLanes, total[g]);
    });
  }
}

// The non-zero entries of x[0..n) as (index, value) pairs, without a branch; returns their count.
inline int nonzero_inputs(const float* x, int n, int32_t* __restrict index, float* __restrict value) {
  int count = 0;
  for (int i = 0; i < n; ++i) {
    index[count] = i;
    value[count] = x[i];
    count += x[i] != 0.0f;
  }
  return count;
}

// y = act(W x + b). y: room for the padded stride.
void dense_forward(const DenseLayer& l, const float* x, float* y, PolicyScratch& s) {
  const int count = nonzero_inputs(x, l.in, s.index.data(), s.value.data());
  sparse_input_product(l.weight, s.index.data(), s.value.data(), count, y);
  with_activation(l.activation, [&](auto act) {
    for (int o = 0; o < l.out; ++o) y[o] = act(y[o] + l.bias[o]);
  });
}

// The sums of a valid convolution, stride 1, by scattering: each non-zero input adds its
// weight rows to the output positions it reaches. sums: positions x stride, (row, col) order.
// For one output the terms arrive in the loops' order: channel, then input row (the kernel
// row ascending), then input column (the kernel column ascending): the plain loop's order over
// the weight's [in][kh][kw], whatever the zeros. nonzero: room for conv_index_size(l) indices.
inline size_t conv_index_size(const ConvLayer& l) {
  const size_t rows = static_cast<size_t>(l.in_channels) * l.in_h;
  return rows + 1 + rows * l.in_w;
}
MMRL_MULTIVERSION void conv_sums(const ConvLayer& l, const float* x, float* sums, int32_t* nonzero) {
  const int kh = l.kernel_h, kw = l.kernel_w, in_w = l.in_w, oh = l.in_h - kh + 1, ow = in_w - kw + 1;
  const int stride = l.weight.stride, rows = l.in_channels * l.in_h;
  // Each input row's non-zero columns, found once for every pass: row r's are cols[starts[r]
  // .. starts[r + 1]) (r = channel * in_h + row).
  int32_t* starts = nonzero;
  int32_t* cols = nonzero + rows + 1;
  int n = 0;
  for (int r = 0; r < rows; ++r) {
    starts[r] = n;
    const float* row = x + static_cast<size_t>(r) * in_w;
    for (int xx = 0; xx < in_w; ++xx) {
      cols[n] = xx;
      n += row[xx] != 0.0f;
    }
  }
  starts[rows] = n;
  std::fill(sums, sums + static_cast<size_t>(oh) * ow * stride, 0.0f);
  for (int c0 = 0; c0 < stride; c0 += 8 * kLanes)  // up to 64 output channels per pass
  with_count_1_to_8(std::min(8, (stride - c0) / kLanes), [&](auto lanes) {
    constexpr int G = decltype(lanes)::value;
    for (int c = 0; c < l.in_channels; ++c)
      for (int yy = 0; yy < l.in_h; ++yy) {
        const int r = c * l.in_h + yy;
        if (starts[r] == starts[r + 1]) continue;
        const float* row = x + static_cast<size_t>(r) * in_w;
        for (int kr = std::max(0, yy - oh + 1); kr <= std::min(kh - 1, yy); ++kr) {
          float* out_row = sums + static_cast<size_t>(yy - kr) * ow * stride + c0;
          const float* w_row = l.weight.rows.data() + static_cast<size_t>((c * kh + kr) * kw) * stride + c0;
          for (int t = starts[r]; t < starts[r + 1]; ++t) {
            const int xx = cols[t];
            const float v = row[xx];
            for (int kq = std::max(0, xx - ow + 1); kq <= std::min(kw - 1, xx); ++kq) {
              float* o = out_row + static_cast<size_t>(xx - kq) * stride;
              const float* wk = w_row + static_cast<size_t>(kq) * stride;
              for (int g = 0; g < G; ++g)
                store_lanes(o + g * kLanes, load_lanes(o + g * kLanes) + v * load_lanes(wk + g * kLanes));
            }
          }
        }
      }
  });
}

// Valid convolution, stride 1; y in (channel, row, col) order.
void conv_forward(const ConvLayer& l, const float* x, float* y, PolicyScratch& s) {
  const int positions = (l.in_h - l.kernel_h + 1) * (l.in_w - l.kernel_w + 1), stride = l.weight.stride;
  float* sums = s.sums.data();
  conv_sums(l, x, sums, s.index.data());
  with_activation(l.activation, [&](auto act) {
    for (int p = 0; p < positions; ++p) {
      const float* from = sums + static_cast<size_t>(p) * stride;
      for (int o = 0; o < l.out_channels; ++o) y[o * positions + p] = act(from[o] + l.bias[o]);
    }
  });
}

Activation activation_of(const ControllerFile& f, int32_t code) {
  if (code < 0 || code > 2) f.fail("section 'policy.activations': unknown activation code " + std::to_string(code));
  return static_cast<Activation>(code);
}

}  // namespace

void TransposedWeights::assign(const std::vector<float>& weight, int out, int in) {
  stride = (out + kLanes - 1) / kLanes * kLanes;
  rows.assign(static_cast<size_t>(in) * stride, 0.0f);
  for (int o = 0; o < out; ++o)
    for (int i = 0; i < in; ++i) rows[static_cast<size_t>(i) * stride + o] = weight[static_cast<size_t>(o) * in + i];
}

void PolicyNet::read_layers(const ControllerFile& f, const std::vector<int32_t>& header) {
  const int n_conv = header[3], n_dense = header[4];
  const auto acts = f.ints("policy.activations", {n_conv + n_dense});
  int c = map_c_, h = map_h_, w = map_w_;
  for (int k = 0; k < n_conv; ++k) {
    const std::string p = "policy.conv" + std::to_string(k);
    ConvLayer l;
    const FileSection& s = f.section(p + ".weight");
    if (s.shape.size() != 4 || s.shape[1] != c || s.shape[2] > h || s.shape[3] > w || s.shape[0] < 1)
      f.fail("section '" + p + ".weight' does not fit a " + std::to_string(c) + " x " + std::to_string(h) + " x " +
             std::to_string(w) + " input");
    l.in_channels = c;
    l.out_channels = static_cast<int>(s.shape[0]);
    l.kernel_h = static_cast<int>(s.shape[2]);
    l.kernel_w = static_cast<int>(s.shape[3]);
    l.in_h = h;
    l.in_w = w;
    l.weight.assign(f.floats(p + ".weight"), l.out_channels, c * l.kernel_h * l.kernel_w);
    l.bias = f.floats(p + ".bias", {l.out_channels});
    l.activation = activation_of(f, acts[k]);
    c = l.out_channels;
    h = h - l.kernel_h + 1;
    w = w - l.kernel_w + 1;
    convs_.push_back(std::move(l));
  }
  int width = kind_ == kMlp ? obs_dim_ : c * h * w;
  for (int k = 0; k < n_dense; ++k) {
    const std::string p = "policy.dense" + std::to_string(k);
    if (kind_ == kConvTower && k == 1) width += vector_size_;  // the vector joins after the map's FC
    DenseLayer l;
    const FileSection& s = f.section(p + ".weight");
    if (s.shape.size() != 2 || s.shape[1] != width || s.shape[0] < 1)
      f.fail("section '" + p + ".weight' does not take " + std::to_string(width) + " inputs");
    l.in = width;
    l.out = static_cast<int>(s.shape[0]);
    l.weight.assign(f.floats(p + ".weight"), l.out, width);
    l.bias = f.floats(p + ".bias", {l.out});
    l.activation = activation_of(f, acts[n_conv + k]);
    width = l.out;
    dense_.push_back(std::move(l));
  }
  if (width != act_dim_) f.fail("the policy's last layer writes " + std::to_string(width) + " values, not act_dim");
}

PolicyNet PolicyNet::from_file(const ControllerFile& f) {
  PolicyNet net;
  const auto header = f.ints("policy.header", {11});
  if (header[0] != kMlp && header[0] != kConvTower) f.fail("section 'policy.header': unknown network kind");
  net.kind_ = static_cast<Kind>(header[0]);
  net.obs_dim_ = header[1];
  net.act_dim_ = header[2];
  if (net.obs_dim_ < 1 || net.obs_dim_ > 1 << 20 || net.act_dim_ < 1 || net.act_dim_ > 1024 || header[3] < 0 ||
      header[3] > 16 || header[4] < 1 || header[4] > 64)
    f.fail("section 'policy.header': sizes out of range");
  if (net.kind_ == kConvTower) {
    net.map_start_ = header[5];
    net.map_c_ = header[6];
    net.map_h_ = header[7];
    net.map_w_ = header[8];
    net.vector_start_ = header[9];
    net.vector_size_ = header[10];
    const int64_t map_size = int64_t(net.map_c_) * net.map_h_ * net.map_w_;
    if (net.map_c_ < 1 || net.map_h_ < 1 || net.map_w_ < 1 || net.map_start_ < 0 || net.vector_start_ < 0 ||
        net.vector_size_ < 0 || net.map_start_ + map_size > net.obs_dim_ ||
        net.vector_start_ + net.vector_size_ > net.obs_dim_ || header[3] < 1 || header[4] < 2)
      f.fail("section 'policy.header': the map or vector segment does not fit the observation");
  }
  net.read_layers(f, header);
  net.obs_scale_ = f.floats("policy.obs_scale", {net.obs_dim_});
  net.obs_shift_ = f.floats("policy.obs_shift", {net.obs_dim_});
  net.obs_clip_ = f.floats("policy.obs_clip", {1})[0];
  net.action_center_ = f.floats("policy.action_center", {net.act_dim_});
  net.action_half_ = f.floats("policy.action_half", {net.act_dim_});
  if (!(net.obs_clip_ > 0)) f.fail("section 'policy.obs_clip' must be positive");
  return net;
}

PolicyScratch PolicyNet::make_scratch() const {
  size_t widest = static_cast<size_t>(obs_dim_);
  for (const auto& l : convs_) {
    widest = std::max(widest, static_cast<size_t>(l.in_channels) * l.in_h * l.in_w);
    widest = std::max(widest, static_cast<size_t>(l.out_channels) * (l.in_h - l.kernel_h + 1) * (l.in_w - l.kernel_w + 1));
  }
  size_t inputs = 0, sums = 0;
  for (const auto& l : dense_) {
    widest = std::max(widest, static_cast<size_t>(std::max(l.in, l.weight.stride)));
    inputs = std::max(inputs, static_cast<size_t>(l.in));
  }
  size_t indices = inputs;
  for (const auto& l : convs_) {
    indices = std::max(indices, conv_index_size(l));
    sums = std::max(sums, static_cast<size_t>(l.weight.stride) * (l.in_h - l.kernel_h + 1) * (l.in_w - l.kernel_w + 1));
  }
  // A dense layer writes its padded stride; the vector segment waits past the widest of them.
  widest = (widest + kLanes - 1) / kLanes * kLanes;
  PolicyScratch s;
  s.sums.assign(sums, 0.0f);
  s.index.assign(indices, 0);
  s.value.assign(inputs, 0.0f);
  s.a.assign(widest + vector_size_, 0.0f);
  s.b.assign(widest + vector_size_, 0.0f);
  return s;
}

void PolicyNet::act(const float* obs, float* action, PolicyScratch& scratch) const {
  float* x = scratch.a.data();
  float* y = scratch.b.data();
  float* normalized = scratch.b.data();
  // The same float operations as torch.addcmul(shift, obs, scale).clamp(-clip, clip).
  for (int k = 0; k < obs_dim_; ++k)
    normalized[k] = std::min(obs_clip_, std::max(-obs_clip_, obs_shift_[k] + obs[k] * obs_scale_[k]));
  size_t first_dense = 0;
  if (kind_ == kMlp) {
    std::copy(normalized, normalized + obs_dim_, x);
  } else {
    // x: the map segment; the vector segment waits at the end of the ping-pong buffer.
    const size_t map_size = static_cast<size_t>(map_c_) * map_h_ * map_w_;
    float* vec = scratch.a.data() + scratch.a.size() - vector_size_;
    std::copy(normalized + vector_start_, normalized + vector_start_ + vector_size_, vec);
    std::copy(normalized + map_start_, normalized + map_start_ + map_size, x);
    for (const auto& l : convs_) {
      conv_forward(l, x, y, scratch);
      std::swap(x, y);
    }
    dense_forward(dense_[0], x, y, scratch);
    std::copy(vec, vec + vector_size_, y + dense_[0].out);
    std::swap(x, y);
    first_dense = 1;
  }
  for (size_t k = first_dense; k < dense_.size(); ++k) {
    dense_forward(dense_[k], x, y, scratch);
    std::swap(x, y);
  }
  for (int k = 0; k < act_dim_; ++k) action[k] = action_center_[k] + action_half_[k] * x[k];
}

size_t PolicyNet::num_parameters() const {
  size_t n = 0;
  for (const auto& l : convs_)
    n += static_cast<size_t>(l.out_channels) * l.in_channels * l.kernel_h * l.kernel_w + l.bias.size();
  for (const auto& l : dense_) n += static_cast<size_t>(l.out) * l.in + l.bias.size();
  return n;
}

}  // namespace mmrl
