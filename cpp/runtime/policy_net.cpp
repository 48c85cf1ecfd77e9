#include "mmrl/policy_net.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include <Eigen/Core>

namespace mmrl {

namespace {

inline float activate(float x, Activation a) {
  switch (a) {
    case Activation::kTanh: return std::tanh(x);
    case Activation::kRelu: return x > 0.0f ? x : 0.0f;
    default: return x;
  }
}

using RowMatrix = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// y = act(W x + b): an Eigen matrix-vector product (SIMD; its sums run in another order than a
// plain loop, within float rounding of torch's own).
void dense_forward(const DenseLayer& l, const float* x, float* y) {
  const Eigen::Map<const RowMatrix> w(l.weight.data(), l.out, l.in);
  const Eigen::Map<const Eigen::VectorXf> xv(x, l.in);
  Eigen::Map<Eigen::VectorXf> yv(y, l.out);
  yv.noalias() = w * xv;
  for (int o = 0; o < l.out; ++o) y[o] = activate(y[o] + l.bias[o], l.activation);
}

// Valid convolution, stride 1, as im2col (cols: (in_channels * kh * kw) x (oh * ow), rows in
// the weight's [in][kh][kw] order) and one matrix product with the (out x in*kh*kw) weights.
void conv_forward(const ConvLayer& l, const float* x, float* y, float* cols) {
  const int oh = l.in_h - l.kernel_h + 1, ow = l.in_w - l.kernel_w + 1;
  const int k_size = l.in_channels * l.kernel_h * l.kernel_w, positions = oh * ow;
  for (int c = 0; c < l.in_channels; ++c) {
    const float* in = x + static_cast<size_t>(c) * l.in_h * l.in_w;
    for (int kr = 0; kr < l.kernel_h; ++kr)
      for (int kq = 0; kq < l.kernel_w; ++kq) {
        float* row = cols + static_cast<size_t>((c * l.kernel_h + kr) * l.kernel_w + kq) * positions;
        for (int r = 0; r < oh; ++r) std::copy(in + (r + kr) * l.in_w + kq, in + (r + kr) * l.in_w + kq + ow, row + r * ow);
      }
  }
  const Eigen::Map<const RowMatrix> w(l.weight.data(), l.out_channels, k_size);
  const Eigen::Map<const RowMatrix> c(cols, k_size, positions);
  Eigen::Map<RowMatrix> out(y, l.out_channels, positions);
  out.noalias() = w * c;
  for (int o = 0; o < l.out_channels; ++o)
    for (int k = 0; k < positions; ++k) y[o * positions + k] = activate(y[o * positions + k] + l.bias[o], l.activation);
}

Activation activation_of(const ControllerFile& f, int32_t code) {
  if (code < 0 || code > 2) f.fail("section 'policy.activations': unknown activation code " + std::to_string(code));
  return static_cast<Activation>(code);
}

}  // namespace

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
    l.weight = f.floats(p + ".weight");
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
    l.weight = f.floats(p + ".weight");
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
  for (const auto& l : dense_) widest = std::max(widest, static_cast<size_t>(std::max(l.in, l.out)));
  size_t cols = 0;
  for (const auto& l : convs_)
    cols = std::max(cols, static_cast<size_t>(l.in_channels) * l.kernel_h * l.kernel_w * (l.in_h - l.kernel_h + 1) *
                              (l.in_w - l.kernel_w + 1));
  PolicyScratch s;
  s.cols.assign(cols, 0.0f);
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
      conv_forward(l, x, y, scratch.cols.data());
      std::swap(x, y);
    }
    dense_forward(dense_[0], x, y);
    std::copy(vec, vec + vector_size_, y + dense_[0].out);
    std::swap(x, y);
    first_dense = 1;
  }
  for (size_t k = first_dense; k < dense_.size(); ++k) {
    dense_forward(dense_[k], x, y);
    std::swap(x, y);
  }
  for (int k = 0; k < act_dim_; ++k) action[k] = action_center_[k] + action_half_[k] * x[k];
}

size_t PolicyNet::num_parameters() const {
  size_t n = 0;
  for (const auto& l : convs_) n += l.weight.size() + l.bias.size();
  for (const auto& l : dense_) n += l.weight.size() + l.bias.size();
  return n;
}

}  // namespace mmrl
