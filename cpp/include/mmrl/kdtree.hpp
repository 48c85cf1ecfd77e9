// Exact k-nearest-neighbour KD-tree over float32 rows, squared L2 distance.
//
// Design (in the spirit of nanoflann, written here):
//   - The caller's points are borrowed (n x dim, row-major, float32) and never copied
//     into another row-major array; the tree keeps an index permutation and a flat,
//     preorder node array (left child = node + 1, right child stored).
//   - For speed the leaves hold a permuted copy of their rows in a blocked layout
//     ("SoA blocks"): kLanes rows per block, dimension-major inside a block, so a leaf
//     scan is a tight loop that the compiler vectorizes across rows. This copy is
//     n * dim floats (plus padding to kLanes). The borrowed array must still outlive the
//     tree: nearest_with_bound reads the bound row from it on every query, and the
//     brute-force paths (search.hpp) scan it.
//   - Every node stores its tight axis-aligned bounding box, so the pruning bound is the
//     true squared distance from the query to the box, not a split-plane distance.
//     Splits: the dimension of widest spread, at the median (O(N log N) build with
//     nth_element; depth <= ceil(log2(N)) + 1).
//   - Search: depth-first, nearer child first, far children pushed with their box bound
//     and skipped on pop when the bound exceeds the current k-th best. Leaf scans abort a
//     block as soon as every lane's partial sum exceeds the k-th best.
//   - Determinism: results are ordered by (squared distance, original index); on equal
//     distance the lowest index wins, so results equal a brute-force scan exactly (both
//     go through lanes_sqdist, the one distance kernel).
//   - Filters: an optional build mask (rows left out of the tree entirely), an optional
//     query mask of allowed rows, an optional excluded index window [lo, hi), and an
//     optional CandidateFilter that refuses rows or adds a cost >= 0 to them (the
//     decision's extension point). Extra costs are never negative, so a box bound is still
//     a lower bound of every filtered cost below it and the search stays exact.
//   - No heap allocation during a query: the traversal stack is a fixed array and the
//     k results live in the caller's output arrays.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <string>
#include <vector>

#include "mmrl/simd.hpp"

namespace mmrl {

constexpr int kMaxDim = 128;  // rows are staged in fixed stack buffers: no heap per query

// The one distance kernel of the library. x is a block of kLanes rows stored
// dimension-major (x[d * kLanes + lane]); adds dims [d_begin, d_end) of each lane's
// squared distance to q into acc, in dimension order. Tree leaves, brute force and the
// continuation bound all call this, so every distance is computed by the same sequence of
// operations (whatever the compiler's FMA contraction does, it does it everywhere) and the
// results compare equal bit for bit.
__attribute__((always_inline)) inline Lanes lanes_sqdist(const float* q, const float* x, int d_begin, int d_end,
                                                      Lanes acc) {
  for (int d = d_begin; d < d_end; ++d) {
    const Lanes diff = q[d] - load_lanes(x + d * kLanes);
    acc += diff * diff;
  }
  return acc;
}

// Squared distances from q to up to kLanes rows of a row-major array (rows[i * dim ..]),
// written to out[0..count). Used for brute force and single rows.
inline void rows_sqdist(const float* q, const float* rows, int count, int dim, float* out) {
  float block[kLanes * kMaxDim];
  for (int d = 0; d < dim; ++d)
    for (int l = 0; l < kLanes; ++l) block[d * kLanes + l] = l < count ? rows[static_cast<int64_t>(l) * dim + d] : 0.0f;
  const Lanes acc = lanes_sqdist(q, block, 0, dim, Lanes{});
  for (int l = 0; l < count; ++l) out[l] = acc[l];
}

// Squared L2 distance between two rows (dim <= kMaxDim), by the shared kernel.
inline float sqdist_row(const float* a, const float* b, int dim) {
  float out;
  rows_sqdist(a, b, 1, dim, &out);
  return out;
}

// A candidate of a match: a database row (its index, and its features in the matched rows),
// or a compressed controller's state (compressed.hpp), which has no row (row -1) and carries
// its own features. kFeatureDim normalized floats either way.
struct Candidate {
  int64_t row = -1;
  const float* features = nullptr;
};

// The extension point of a match: a rule that refuses candidates or makes them dearer (a clip
// the user banned, obstacles on a candidate's path, a style to keep). A search returns the
// candidate of least filtered cost, squared distance + extra_cost(candidate), exactly as a
// brute-force scan with the same filter does. Both motion sources (the database's rows and a
// compressed controller's states) are priced through this one method: a rule that keeps to
// clips returns 0 for a candidate without a row.
class CandidateFilter {
 public:
  virtual ~CandidateFilter() = default;
  // Extra cost of returning `candidate`, in squared normalized feature distance: 0 leaves it
  // as it is, +inf (or NaN) refuses it; a negative value counts as 0 (a filter can only make
  // candidates dearer, which keeps the tree's pruning exact). Called only for candidates whose
  // distance alone could still win, so a costly rule runs on few of them.
  virtual float extra_cost(const Candidate& candidate) const = 0;
  // The filter a decision retries with when this one refuses every candidate (decision.hpp's
  // decision_match): a filter built over another returns it; null falls back to no filter.
  virtual const CandidateFilter* fallback() const { return nullptr; }
};

// Squared distance d of a candidate plus the filter's extra cost (+inf when refused). Tree,
// brute force and the compressed decision all go through this, so filtered costs agree bit
// for bit.
inline float filtered_cost(float d, const CandidateFilter* filter, const Candidate& candidate) {
  if (filter == nullptr) return d;
  const float extra = filter->extra_cost(candidate);
  if (!(extra < std::numeric_limits<float>::infinity())) return std::numeric_limits<float>::infinity();
  return extra > 0.0f ? d + extra : d;
}
// The same for row i of points (dim floats a row).
inline float filtered_cost(float d, const CandidateFilter* filter, int64_t i, const float* points, int dim) {
  if (filter == nullptr) return d;
  return filtered_cost(d, filter, Candidate{i, points + i * dim});
}

// What a query may return. Default: every row of the tree.
struct SearchFilter {
  const uint8_t* allowed = nullptr;  // optional, n entries (original row order); 0 = never return
  int64_t exclude_lo = 0;            // rows in [exclude_lo, exclude_hi) are never returned
  int64_t exclude_hi = 0;            // (empty window when hi <= lo)
  const CandidateFilter* candidates = nullptr;  // optional: refuses rows or adds to their cost
};

class KDTree {
 public:
  static constexpr int kLanes = mmrl::kLanes;  // rows per SoA block
  static constexpr int kMaxDim = mmrl::kMaxDim;
  static constexpr int kMaxDepth = 96;   // median splits keep depth near log2(n)

  // points: n x dim row-major float32, borrowed (see header comment). leaf_size >= 1.
  // build_mask (optional, n entries): rows with 0 are left out of the tree.
  KDTree(const float* points, int64_t num_points, int dim, int leaf_size = 16, const uint8_t* build_mask = nullptr)
      : points_(points), n_(num_points), dim_(dim), leaf_size_(leaf_size) {
    if (num_points < 0) throw std::invalid_argument("KDTree: num_points must be >= 0");
    if (num_points > 0 && points == nullptr) throw std::invalid_argument("KDTree: points is null");
    if (dim <= 0 || dim > kMaxDim)
      throw std::invalid_argument("KDTree: dim must be in [1, " + std::to_string(kMaxDim) + "], got " +
                                  std::to_string(dim));
    if (leaf_size < 1) throw std::invalid_argument("KDTree: leaf_size must be >= 1");
    if (num_points > std::numeric_limits<int32_t>::max() / 2)
      throw std::invalid_argument("KDTree: too many points");
    dim_padded_ = (dim + kLanes - 1) / kLanes * kLanes;
    build(build_mask);
  }

  int64_t size() const { return n_; }               // rows in the borrowed array
  int64_t indexed_size() const { return static_cast<int64_t>(perm_.size()); }  // rows in the tree
  int dim() const { return dim_; }
  int leaf_size() const { return leaf_size_; }
  int depth() const { return depth_; }
  int64_t num_nodes() const { return static_cast<int64_t>(nodes_.size()); }
  // Bytes the tree holds (the rows it searches are borrowed, not counted).
  size_t memory_bytes() const {
    return sizeof(Node) * nodes_.size() + sizeof(float) * (box_.size() + blocks_.size() + block_init_.size()) +
           sizeof(int32_t) * (perm_.size() + block_index_.size());
  }
  const float* points() const { return points_; }
  const std::vector<int32_t>& permutation() const { return perm_; }

  // Exact k nearest rows of `query` (dim floats). Fills out_indices[0..k) and
  // out_sqdist[0..k) in increasing (squared distance, index) order; slots without a
  // result (filtered out) get index -1 and distance +inf. Returns the number found.
  // k must be <= the number of indexed rows (an empty tree accepts k = 1 and finds none).
  int knn(const float* query, int k, int64_t* out_indices, float* out_sqdist, const SearchFilter& filter = {}) const {
    if (query == nullptr || out_indices == nullptr || out_sqdist == nullptr)
      throw std::invalid_argument("KDTree::knn: null pointer");
    if (k < 1) throw std::invalid_argument("KDTree::knn: k must be >= 1");
    if (k > std::max<int64_t>(1, indexed_size()))
      throw std::invalid_argument("KDTree::knn: k = " + std::to_string(k) + " exceeds the " +
                                  std::to_string(indexed_size()) + " indexed rows");
    std::fill(out_indices, out_indices + k, int64_t{-1});
    std::fill(out_sqdist, out_sqdist + k, std::numeric_limits<float>::infinity());
    if (k == 1)
      search<true>(query, 1, out_indices, out_sqdist, filter, /*bound_is_set=*/false);
    else
      search<false>(query, k, out_indices, out_sqdist, filter, /*bound_is_set=*/false);
    int found = 0;
    while (found < k && out_indices[found] >= 0) ++found;
    return found;
  }

  // knn for M queries (M x dim row-major), results M x k row-major. Serial; see
  // mmrl::Matcher for the threaded motion-matching batch.
  void knn_batch(const float* queries, int64_t num_queries, int k, int64_t* out_indices, float* out_sqdist,
                 const SearchFilter& filter = {}) const {
    if (num_queries < 0) throw std::invalid_argument("KDTree::knn_batch: num_queries must be >= 0");
    if (num_queries > 0 && (queries == nullptr || out_indices == nullptr || out_sqdist == nullptr))
      throw std::invalid_argument("KDTree::knn_batch: null pointer");
    for (int64_t q = 0; q < num_queries; ++q)
      knn(queries + q * dim_, k, out_indices + q * k, out_sqdist + q * k, filter);
  }

  // Nearest row, starting from a known candidate: bound_index's distance (any row of the
  // borrowed array, -1 for none) minus transition_cost (>= 0) is the starting best, and only an
  // allowed row strictly closer than that replaces it (ties keep the bound): with a margin,
  // another row must beat the bound by more than the margin. Returns the index (-1 if none)
  // and its own cost (the bound's true distance when it is kept).
  int64_t nearest_with_bound(const float* query, int64_t bound_index, float* out_cost,
                             const SearchFilter& filter = {}, float transition_cost = 0.0f) const {
    if (query == nullptr) throw std::invalid_argument("KDTree::nearest_with_bound: null query");
    if (bound_index < -1 || bound_index >= n_)
      throw std::out_of_range("KDTree::nearest_with_bound: bound_index " + std::to_string(bound_index) +
                              " is outside [-1, " + std::to_string(n_) + ")");
    if (!(transition_cost >= 0.0f) || !std::isfinite(transition_cost))
      throw std::invalid_argument("KDTree::nearest_with_bound: transition_cost must be finite and >= 0");
    int64_t idx = -1;
    float cost = std::numeric_limits<float>::infinity();
    float bound_cost = cost;
    bool bound_set = false;
    if (bound_index >= 0) {
      // The bound is a candidate like any other: a filter may make it dearer or refuse it
      // (then the search starts without one).
      bound_cost = filtered_cost(sqdist_row(query, points_ + bound_index * dim_, dim_), filter.candidates, bound_index,
                                  points_, dim_);
      if (bound_cost < std::numeric_limits<float>::infinity()) {
        idx = bound_index;
        cost = bound_cost - transition_cost;
        bound_set = true;
      }
    }
    search<true>(query, 1, &idx, &cost, filter, bound_set);
    if (idx == bound_index) cost = bound_cost;
    if (out_cost) *out_cost = cost;
    return idx;
  }

 private:
  struct Node {
    int32_t begin, end;   // range in perm_ (leaf rows, or all rows below an inner node)
    int32_t right;        // right child; -1 for a leaf (left child is this + 1)
    int32_t first_block;  // leaves: first SoA block of their rows
  };

  // ---- build --------------------------------------------------------------------------
  void build(const uint8_t* build_mask) {
    perm_.clear();
    perm_.reserve(static_cast<size_t>(n_));
    for (int64_t i = 0; i < n_; ++i)
      if (!build_mask || build_mask[i]) perm_.push_back(static_cast<int32_t>(i));
    if (perm_.empty()) return;
    const size_t approx_nodes = 2 * (perm_.size() / static_cast<size_t>(leaf_size_) + 1);
    nodes_.reserve(approx_nodes);
    box_.reserve(approx_nodes * 2 * dim_padded_);
    std::vector<float> lo(dim_), hi(dim_);
    build_node(0, static_cast<int32_t>(perm_.size()), 1, lo, hi);
    // Blocked, permuted copy of the leaf rows. Padding lanes carry +inf as their starting
    // sum so they can never be returned.
    blocks_.assign(static_cast<size_t>(num_blocks_) * dim_ * kLanes, 0.0f);
    block_index_.assign(static_cast<size_t>(num_blocks_) * kLanes, -1);
    block_init_.assign(static_cast<size_t>(num_blocks_) * kLanes, std::numeric_limits<float>::infinity());
    for (const Node& node : nodes_) {
      if (node.right >= 0) continue;
      for (int32_t r = node.begin; r < node.end; ++r) {
        const int32_t local = r - node.begin;
        const size_t b = static_cast<size_t>(node.first_block + local / kLanes);
        const int lane = local % kLanes;
        const float* row = points_ + static_cast<int64_t>(perm_[r]) * dim_;
        for (int d = 0; d < dim_; ++d) blocks_[(b * dim_ + d) * kLanes + lane] = row[d];
        block_index_[b * kLanes + lane] = perm_[r];
        block_init_[b * kLanes + lane] = 0.0f;
      }
    }
  }

  int32_t build_node(int32_t begin, int32_t end, int depth, std::vector<float>& lo, std::vector<float>& hi) {
    depth_ = std::max(depth_, depth);
    if (depth > kMaxDepth) throw std::logic_error("KDTree: depth limit exceeded");
    const int32_t id = static_cast<int32_t>(nodes_.size());
    nodes_.push_back(Node{begin, end, -1, -1});
    // Tight bounding box of the rows below this node; padded dims get (-inf, +inf) so
    // they contribute nothing to a box distance.
    std::fill(lo.begin(), lo.end(), std::numeric_limits<float>::infinity());
    std::fill(hi.begin(), hi.end(), -std::numeric_limits<float>::infinity());
    for (int32_t r = begin; r < end; ++r) {
      const float* row = points_ + static_cast<int64_t>(perm_[r]) * dim_;
      for (int d = 0; d < dim_; ++d) {
        lo[d] = std::min(lo[d], row[d]);
        hi[d] = std::max(hi[d], row[d]);
      }
    }
    const size_t box_at = box_.size();
    box_.resize(box_at + 2 * dim_padded_);
    for (int d = 0; d < dim_padded_; ++d) {
      box_[box_at + d] = d < dim_ ? lo[d] : -std::numeric_limits<float>::infinity();
      box_[box_at + dim_padded_ + d] = d < dim_ ? hi[d] : std::numeric_limits<float>::infinity();
    }
    int split_dim = 0;
    float spread = -1.0f;
    for (int d = 0; d < dim_; ++d)
      if (hi[d] - lo[d] > spread) spread = hi[d] - lo[d], split_dim = d;
    if (end - begin <= leaf_size_ || !(spread > 0.0f)) {  // small, or all rows identical
      nodes_[id].first_block = num_blocks_;
      num_blocks_ += (end - begin + kLanes - 1) / kLanes;
      return id;
    }
    const int32_t mid = begin + (end - begin) / 2;
    std::nth_element(perm_.begin() + begin, perm_.begin() + mid, perm_.begin() + end, [&](int32_t a, int32_t b) {
      const float va = points_[static_cast<int64_t>(a) * dim_ + split_dim];
      const float vb = points_[static_cast<int64_t>(b) * dim_ + split_dim];
      return va < vb || (va == vb && a < b);
    });
    build_node(begin, mid, depth + 1, lo, hi);
    const int32_t right = build_node(mid, end, depth + 1, lo, hi);
    nodes_[id].right = right;
    return id;
  }

  // ---- search -------------------------------------------------------------------------
  // Squared distance from q (padded to dim_padded_) to node's box. Accumulated in kLanes
  // partial sums so it vectorizes; its rounding differs from sqdist_row, hence kBoundSlack.
  float box_sqdist(const float* q, int32_t node) const {
    const float* lo = box_.data() + static_cast<size_t>(node) * 2 * dim_padded_;
    const float* hi = lo + dim_padded_;
    Lanes acc = {};
    const Lanes zero = {};
    for (int d0 = 0; d0 < dim_padded_; d0 += kLanes) {
      const Lanes qv = load_lanes(q + d0);
      const Lanes below = load_lanes(lo + d0) - qv;
      const Lanes above = qv - load_lanes(hi + d0);
      Lanes gap = below > above ? below : above;
      gap = gap > zero ? gap : zero;
      acc += gap * gap;
    }
    float s = 0.0f;
    for (int l = 0; l < kLanes; ++l) s += acc[l];
    return s;
  }

  static bool all_greater(Lanes acc, float w) {
    const LaneMask m = acc > w;
    int64_t words[kLanes / 2];
    std::memcpy(words, &m, sizeof(words));
    int64_t all = -1;
    for (int i = 0; i < kLanes / 2; ++i) all &= words[i];
    return all == -1;
  }

  // A box bound computed in float may exceed a contained row's float distance by a few
  // ulps (different summation order); shrink it by far more than that before pruning.
  static constexpr float kBoundSlack = 1.0f - 1e-5f;

  // Inserts candidate (d, idx) into the sorted result list if it ranks before the current
  // k-th entry. Rank: distance, then index; an entry at position 0 that is the bound
  // (bound_rank) wins ties against everything.
  static void insert(int k, int64_t* idx, float* dist, float d, int64_t i) {
    int pos = k - 1;
    while (pos > 0 && (d < dist[pos - 1] || (d == dist[pos - 1] && i < idx[pos - 1]))) {
      dist[pos] = dist[pos - 1];
      idx[pos] = idx[pos - 1];
      --pos;
    }
    dist[pos] = d;
    idx[pos] = i;
  }

  // kOne: k == 1, the motion-matching hot path (no sorted list to maintain).
  template <bool kOne>
  void search(const float* query, int k, int64_t* out_idx, float* out_d, const SearchFilter& filter,
              bool bound_is_set) const {
    if (perm_.empty()) return;
    alignas(64) float q[kMaxDim] = {};
    std::copy(query, query + dim_, q);  // padding dims stay 0
    // With a bound set (k == 1), out_idx[0] holds the bound until something strictly better.
    bool best_is_bound = bound_is_set;
    auto worst = [&]() { return out_d[k - 1]; };

    struct Pending {
      int32_t node;
      float bound;
    };
    std::array<Pending, kMaxDepth + 2> stack;
    int top = 0;
    stack[top++] = Pending{0, box_sqdist(q, 0) * kBoundSlack};
    while (top > 0) {
      const Pending p = stack[--top];
      if (p.bound > worst()) continue;
      int32_t node = p.node;
      // Descend to a leaf, nearer child first.
      while (nodes_[node].right >= 0) {
        const int32_t left = node + 1, right = nodes_[node].right;
        const float bl = box_sqdist(q, left) * kBoundSlack;
        const float br = box_sqdist(q, right) * kBoundSlack;
        const bool left_first = bl <= br;
        const int32_t near = left_first ? left : right, far = left_first ? right : left;
        const float bnear = left_first ? bl : br, bfar = left_first ? br : bl;
        const float w = worst();
        if (bfar <= w) stack[top++] = Pending{far, bfar};
        if (bnear > w) {
          node = -1;
          break;
        }
        node = near;
      }
      if (node < 0) continue;
      scan_leaf<kOne>(q, nodes_[node], k, out_idx, out_d, filter, best_is_bound);
    }
  }

  template <bool kOne>
  void scan_leaf(const float* q, const Node& leaf, int k, int64_t* out_idx, float* out_d, const SearchFilter& filter,
                 bool& best_is_bound) const {
    const int32_t nb = (leaf.end - leaf.begin + kLanes - 1) / kLanes;
    for (int32_t b = leaf.first_block; b < leaf.first_block + nb; ++b) {
      const float* x = blocks_.data() + static_cast<size_t>(b) * dim_ * kLanes;
      // One lane per row; each lane accumulates in dimension order like every distance here.
      Lanes acc = load_lanes(block_init_.data() + static_cast<size_t>(b) * kLanes);
      float w = out_d[k - 1];
      bool pruned = false;
      // Checkpoint every 8 dims: stop once every lane's partial sum is past the k-th best
      // (partial sums only grow, so none of these rows can rank).
      for (int d0 = 0; d0 < dim_; d0 += 8) {
        const int d1 = std::min(dim_, d0 + 8);
        acc = lanes_sqdist(q, x, d0, d1, acc);
        if (d1 < dim_ && all_greater(acc, w)) {
          pruned = true;
          break;
        }
      }
      if (pruned) continue;
      for (int l = 0; l < kLanes; ++l) {
        float d = acc[l];
        if (d > w) continue;
        const int64_t i = block_index_[static_cast<size_t>(b) * kLanes + l];
        if (i < 0) continue;  // padding lane
        if (i >= filter.exclude_lo && i < filter.exclude_hi) continue;
        if (filter.allowed && !filter.allowed[i]) continue;
        if (filter.candidates) {
          d = filtered_cost(d, filter.candidates, i, points_, dim_);
          if (d == std::numeric_limits<float>::infinity() || d > w) continue;  // refused, or dearer now
        }
        // Tie with the k-th entry: a lower index wins, but nothing beats the bound on a tie.
        if (d == w && out_idx[k - 1] >= 0 && (best_is_bound || i > out_idx[k - 1])) continue;
        if (kOne) {
          out_d[0] = d;
          out_idx[0] = i;
        } else {
          insert(k, out_idx, out_d, d, i);
        }
        best_is_bound = false;
        w = out_d[k - 1];
      }
    }
  }

  const float* points_;
  int64_t n_;
  int dim_, dim_padded_ = 0, leaf_size_;
  int depth_ = 0;
  int32_t num_blocks_ = 0;
  std::vector<int32_t> perm_;        // tree order -> original row
  std::vector<Node> nodes_;          // preorder
  std::vector<float> box_;           // per node: lo[dim_padded_], hi[dim_padded_]
  std::vector<float> blocks_;        // SoA blocks: [block][dim][lane]
  std::vector<int32_t> block_index_; // [block][lane] -> original row, -1 = padding
  std::vector<float> block_init_;    // [block][lane] -> 0, or +inf for padding
};

}  // namespace mmrl
