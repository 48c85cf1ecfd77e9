// Motion-matching search: exact nearest neighbour over the database's normalized,
// weighted feature rows (plain squared L2 on those rows).
//
//   brute_force_knn / brute_force_match  the reference: a row-major scan in index order.
//   Matcher                              the production search: a KDTree (kdtree.hpp) over
//                                        the valid rows, single and batched queries.
//
// Every distance goes through lanes_sqdist (kdtree.hpp), so the Matcher returns
// exactly what brute force returns (same index, bit-identical cost).
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <string>

#include "mmrl/kdtree.hpp"
#include "mmrl/threadpool.hpp"

// The search entry points (Matcher::match, brute_force_match, brute_force_knn) are
// MMRL_MULTIVERSION (simd.hpp): AVX2 and baseline clones with the same bits.

namespace mmrl {

// k nearest rows of `query` among `points` (n x dim, row-major), ranked by (squared
// distance, index). Same contract as KDTree::knn (slots without a result: -1 / +inf).
int brute_force_knn(const float* points, int64_t num_points, int dim, const float* query, int k,
                    int64_t* out_indices, float* out_sqdist, const SearchFilter& filter = {});

// Motion-matching semantics: the nearest row with valid[i] != 0 outside
// [exclude_lo, exclude_hi), unless bound_index >= 0 is at least as close (the current
// frame's continuation: its cost is the starting best and wins ties). With a candidate
// filter (kdtree.hpp) every cost, the bound's included, is the filtered cost, and refused
// rows (the bound too) are never returned. Returns the row (-1 when nothing is allowed and
// there is no bound) and writes its cost.
int64_t brute_force_match(const float* points, int64_t num_points, int dim, const uint8_t* valid,
                          const float* query, int64_t exclude_lo, int64_t exclude_hi, int64_t bound_index,
                          float* out_cost, float transition_cost = 0.0f, const CandidateFilter* candidates = nullptr);

struct MatcherOptions {
  int leaf_size = 16;                // rows per KD-tree leaf (a sweep in bench/ picks this)
  int64_t brute_force_below = 512;   // fewer valid rows than this: one leaf, i.e. a blocked scan
};

// The most candidates a shortlist match (Matcher::match_shortlist) takes per query, and the
// most queries it takes them from.
constexpr int kMaxShortlist = 256;
constexpr int kMaxShortlistQueries = 13;

// The shortlist rule, by brute force (the reference): the `shortlist` nearest valid rows
// outside [exclude_lo, exclude_hi) by plain squared distance (brute_force_knn: ordered by
// distance, then index), re-ranked by filtered cost (kdtree.hpp's filtered_cost), with the
// continuation rule of brute_force_match for bound_index: the bound's filtered cost less
// transition_cost is the starting best, and a shortlisted row replaces the best only when its
// filtered cost is strictly lower (the first of equal costs in shortlist order wins between
// rows). Returns -1 when the filter refuses every shortlisted row and the bound.
// 1 <= shortlist <= kMaxShortlist.
//
// With num_queries > 1 (queries: num_queries x dim, the first the match's own query), the
// shortlist is the union of the first query's `shortlist` nearest rows and each other query's
// `other_shortlist` nearest (e.g. the query's trajectory turned left and right, so a costly
// filter sees turns too), ranked by plain distance to the first query (then index); the rest
// is the same. 1 <= num_queries <= kMaxShortlistQueries, 1 <= other_shortlist <= kMaxShortlist.
//
// extra_rows (num_extra <= kMaxExtraRows row numbers in [-1, num_points); -1 entries, and rows
// that are not valid or lie in the exclusion window, are skipped; e.g. the nearest rows of fixed
// queries found ahead of time, decision.hpp's EscapeTable) join the union the same way.
constexpr int kMaxExtraRows = 256;
int64_t brute_force_match_shortlist(const float* points, int64_t num_points, int dim, const uint8_t* valid,
                                    const float* query, int shortlist, int64_t exclude_lo, int64_t exclude_hi,
                                    int64_t bound_index, float* out_cost, float transition_cost,
                                    const CandidateFilter* candidates, int num_queries = 1,
                                    int other_shortlist = 1, const int32_t* extra_rows = nullptr, int num_extra = 0);

class Matcher {
 public:
  // rows: n x dim normalized features, row-major, borrowed: must outlive the Matcher.
  // valid: n flags (1 = may be returned), copied into the tree structure; null = all valid.
  Matcher(const float* rows, int64_t num_rows, int dim, const uint8_t* valid, const MatcherOptions& options = {});

  int64_t num_rows() const { return tree_.size(); }
  int64_t num_valid() const { return tree_.indexed_size(); }
  int dim() const { return tree_.dim(); }
  const KDTree& tree() const { return tree_; }

  // One query (dim floats). See brute_force_match for the semantics; exclude window and
  // bound_index are in original row numbers. out_cost may be null.
  int64_t match(const float* query, int64_t exclude_lo = 0, int64_t exclude_hi = 0, int64_t bound_index = -1,
                float* out_cost = nullptr, float transition_cost = 0.0f,
                const CandidateFilter* candidates = nullptr) const;

  // The shortlist rule (brute_force_match_shortlist) through the tree's exact k-NN: the same
  // result, bit for bit. A costly filter then runs on at most shortlist + 1 rows, however
  // many rows it makes dearer. Allocates nothing.
  int64_t match_shortlist(const float* query, int shortlist, int64_t exclude_lo, int64_t exclude_hi,
                          int64_t bound_index, float* out_cost, float transition_cost,
                          const CandidateFilter* candidates, int num_queries = 1, int other_shortlist = 1,
                          const int32_t* extra_rows = nullptr, int num_extra = 0) const;

  // A table derived from this matcher's rows, built once by build() (returning
  // std::shared_ptr<const T>) under a lock on first request for `key` and shared by every
  // later caller (the envs and runtime characters over one database). Not for hot paths.
  template <class T, class Build>
  std::shared_ptr<const T> cached(const std::string& key, Build&& build) const {
    std::lock_guard<std::mutex> lock(cache_->mutex);
    std::shared_ptr<const void>& slot = cache_->tables[key];
    if (!slot) slot = std::shared_ptr<const T>(build());
    return std::static_pointer_cast<const T>(slot);
  }

  // M queries (M x dim row-major) across the pool. Per-query exclude windows and bound
  // indices are optional arrays of M entries (null = none). Allocates nothing.
  void match_batch(const float* queries, int64_t num_queries, int64_t* out_indices, float* out_costs,
                   ThreadPool& pool, const int64_t* exclude_lo = nullptr, const int64_t* exclude_hi = nullptr,
                   const int64_t* bound_indices = nullptr) const;

  // The same contract as match_batch, answered by brute_force_match (tests, benchmarks).
  void brute_force_batch(const float* queries, int64_t num_queries, int64_t* out_indices, float* out_costs,
                         ThreadPool& pool, const int64_t* exclude_lo = nullptr, const int64_t* exclude_hi = nullptr,
                         const int64_t* bound_indices = nullptr) const;

 private:
  const float* rows_;
  const uint8_t* valid_;
  KDTree tree_;
  struct Cache {
    std::mutex mutex;
    std::map<std::string, std::shared_ptr<const void>> tables;
  };
  std::unique_ptr<Cache> cache_ = std::make_unique<Cache>();
};

// The public k-NN (mmrl.KDTree.query) through multiversioned entry points, so a portable
// build answers it with the AVX2 clone where the CPU has one, like the Matcher. Same
// contract and results, bit for bit, as KDTree::knn and KDTree::knn_batch (kdtree.hpp).
int kdtree_knn(const KDTree& tree, const float* query, int k, int64_t* out_indices, float* out_sqdist,
               const SearchFilter& filter = {});
void kdtree_knn_batch(const KDTree& tree, const float* queries, int64_t num_queries, int k, int64_t* out_indices,
                      float* out_sqdist, const SearchFilter& filter = {});

// The same batch across the pool: contiguous chunks of queries, each answered by the serial
// kdtree_knn_batch above (one clone dispatch per chunk). Checks everything before the workers
// start (nothing throws inside them). Results do not depend on the number of threads.
void kdtree_knn_batch(const KDTree& tree, const float* queries, int64_t num_queries, int k, int64_t* out_indices,
                      float* out_sqdist, ThreadPool& pool, const SearchFilter& filter = {});

}  // namespace mmrl
