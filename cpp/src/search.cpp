#include "mmrl/search.hpp"

#include <algorithm>
#include <utility>
#include <limits>
#include <stdexcept>
#include <string>

namespace mmrl {

namespace {

void check_points(const float* points, int64_t num_points, int dim, const char* who) {
  if (num_points < 0) throw std::invalid_argument(std::string(who) + ": num_points must be >= 0");
  if (num_points > 0 && points == nullptr) throw std::invalid_argument(std::string(who) + ": points is null");
  if (dim <= 0 || dim > kMaxDim)
    throw std::invalid_argument(std::string(who) + ": dim must be in [1, " + std::to_string(kMaxDim) + "]");
}

bool is_allowed(int64_t i, const SearchFilter& f) {
  return !(i >= f.exclude_lo && i < f.exclude_hi) && (!f.allowed || f.allowed[i]);
}

}  // namespace

MMRL_MULTIVERSION int brute_force_knn(const float* points, int64_t num_points, int dim, const float* query, int k,
                    int64_t* out_indices, float* out_sqdist, const SearchFilter& filter) {
  check_points(points, num_points, dim, "brute_force_knn");
  if (query == nullptr || out_indices == nullptr || out_sqdist == nullptr)
    throw std::invalid_argument("brute_force_knn: null pointer");
  if (k < 1) throw std::invalid_argument("brute_force_knn: k must be >= 1");
  if (k > std::max<int64_t>(1, num_points))
    throw std::invalid_argument("brute_force_knn: k = " + std::to_string(k) + " exceeds the " +
                                std::to_string(num_points) + " rows");
  for (int j = 0; j < k; ++j) {
    out_indices[j] = -1;
    out_sqdist[j] = std::numeric_limits<float>::infinity();
  }
  int found = 0;
  float dist[kLanes];
  for (int64_t i = 0; i < num_points; ++i) {
    if (i % kLanes == 0)
      rows_sqdist(query, points + i * dim, static_cast<int>(std::min<int64_t>(kLanes, num_points - i)), dim, dist);
    if (!is_allowed(i, filter)) continue;
    const float d = filtered_cost(dist[i % kLanes], filter.candidates, i, points, dim);
    if (d == std::numeric_limits<float>::infinity()) continue;  // refused by the candidate filter
    // Scanning in index order, a tie never displaces an earlier (lower) index.
    if (found == k && !(d < out_sqdist[k - 1])) continue;
    int pos = found < k ? found++ : k - 1;
    while (pos > 0 && d < out_sqdist[pos - 1]) {
      out_sqdist[pos] = out_sqdist[pos - 1];
      out_indices[pos] = out_indices[pos - 1];
      --pos;
    }
    out_sqdist[pos] = d;
    out_indices[pos] = i;
  }
  return found;
}

namespace {

// The continuation rule's running best, shared by brute_force_match and the shortlist: the
// bound's filtered cost less the transition cost is the starting best (a refused bound is no
// bound), and a row replaces the best only with a strictly lower filtered cost (the first of
// equal costs wins when there is no best yet). The reported cost is the bound's own.
class RunningMatch {
 public:
  RunningMatch(const float* points, int dim, const float* query, int64_t bound_index, float transition_cost,
               const CandidateFilter* candidates)
      : bound_(bound_index) {
    if (bound_index < 0) return;
    bound_cost_ = filtered_cost(sqdist_row(query, points + bound_index * dim, dim), candidates, bound_index, points, dim);
    if (bound_cost_ < kInf) {
      best_ = bound_index;
      best_cost_ = bound_cost_ - transition_cost;
    }
  }
  float best_cost() const { return best_cost_; }
  void offer(int64_t i, float cost) {
    if (cost == kInf) return;  // refused by the candidate filter
    if (cost < best_cost_ || (best_ < 0 && cost == best_cost_)) {
      best_cost_ = cost;
      best_ = i;
    }
  }
  int64_t finish(float* out_cost) const {
    if (out_cost) *out_cost = best_ == bound_ ? bound_cost_ : best_cost_;
    return best_;
  }

 private:
  static constexpr float kInf = std::numeric_limits<float>::infinity();
  int64_t bound_, best_ = -1;
  float best_cost_ = kInf, bound_cost_ = kInf;
};

}  // namespace

MMRL_MULTIVERSION int64_t brute_force_match(const float* points, int64_t num_points, int dim, const uint8_t* valid,
                          const float* query, int64_t exclude_lo, int64_t exclude_hi, int64_t bound_index,
                          float* out_cost, float transition_cost, const CandidateFilter* candidates) {
  check_points(points, num_points, dim, "brute_force_match");
  if (query == nullptr) throw std::invalid_argument("brute_force_match: null query");
  if (bound_index >= num_points) throw std::out_of_range("brute_force_match: bound_index out of range");
  if (!(transition_cost >= 0.0f) || !std::isfinite(transition_cost))
    throw std::invalid_argument("brute_force_match: transition_cost must be finite and >= 0");
  RunningMatch match(points, dim, query, bound_index, transition_cost, candidates);
  float dist[kLanes];
  for (int64_t i = 0; i < num_points; ++i) {
    if (i % kLanes == 0)
      rows_sqdist(query, points + i * dim, static_cast<int>(std::min<int64_t>(kLanes, num_points - i)), dim, dist);
    if ((valid && !valid[i]) || (i >= exclude_lo && i < exclude_hi)) continue;
    match.offer(i, filtered_cost(dist[i % kLanes], candidates, i, points, dim));
  }
  return match.finish(out_cost);
}

namespace {

void check_shortlist(int shortlist, float transition_cost, int num_queries, int other_shortlist, const char* who) {
  if (num_queries > 1 && (other_shortlist < 1 || other_shortlist > kMaxShortlist))
    throw std::invalid_argument(std::string(who) + ": other_shortlist must be between 1 and " +
                                std::to_string(kMaxShortlist) + ", got " + std::to_string(other_shortlist));
  if (shortlist < 1 || shortlist > kMaxShortlist)
    throw std::invalid_argument(std::string(who) + ": shortlist must be between 1 and " + std::to_string(kMaxShortlist) +
                                ", got " + std::to_string(shortlist));
  if (num_queries < 1 || num_queries > kMaxShortlistQueries)
    throw std::invalid_argument(std::string(who) + ": num_queries must be between 1 and " +
                                std::to_string(kMaxShortlistQueries) + ", got " + std::to_string(num_queries));
  if (!(transition_cost >= 0.0f) || !std::isfinite(transition_cost))
    throw std::invalid_argument(std::string(who) + ": transition_cost must be finite and >= 0");
}

void check_extra(const int32_t* extra_rows, int num_extra, int64_t num_points, const char* who) {
  if (num_extra < 0 || num_extra > kMaxExtraRows || (num_extra > 0 && extra_rows == nullptr))
    throw std::invalid_argument(std::string(who) + ": num_extra must be between 0 and " +
                                std::to_string(kMaxExtraRows) + " with rows, got " + std::to_string(num_extra));
  for (int r = 0; r < num_extra; ++r)
    if (extra_rows[r] < -1 || extra_rows[r] >= num_points)
      throw std::out_of_range(std::string(who) + ": extra row " + std::to_string(extra_rows[r]) + " is outside [-1, " +
                              std::to_string(num_points) + ")");
}

// The union of several queries' k-NN lists (rows[q * k ..], found[q] each) in place: distinct
// rows, ranked by plain distance to the first query (sqdist_row, the kernel every search uses),
// then index. Returns the count; rows and sqdist then hold the ranked union.
int merge_shortlists(const float* points, int dim, const float* query, int64_t* rows, float* sqdist, const int* found,
                     int num_queries, int k) {
  int n = 0;
  for (int q = 0; q < num_queries; ++q)
    for (int r = 0; r < found[q]; ++r) rows[n++] = rows[q * k + r];
  std::sort(rows, rows + n);
  n = static_cast<int>(std::unique(rows, rows + n) - rows);
  std::pair<float, int64_t> ranked[kMaxShortlist * (kMaxShortlistQueries + 1)];
  for (int r = 0; r < n; ++r) ranked[r] = {sqdist_row(query, points + rows[r] * dim, dim), rows[r]};
  std::sort(ranked, ranked + n);
  for (int r = 0; r < n; ++r) sqdist[r] = ranked[r].first, rows[r] = ranked[r].second;
  return n;
}

// The re-ranking of a shortlist (found rows, ordered as k-NN orders them) with the
// continuation rule; shared by the tree and the brute force so both decide alike.
// Offers ranked rows to a running match. Rows come by plain distance and extra costs are >= 0:
// once a row's distance reaches the best filtered cost, no later row can beat it (a replacement
// must be strictly lower).
template <class Ranked>  // ranked(r): the r-th (plain distance, row) pair
void offer_ranked(RunningMatch& match, const float* points, int dim, int found, Ranked ranked, int64_t bound_index,
                  const CandidateFilter* candidates) {
  for (int r = 0; r < found; ++r) {
    const std::pair<float, int64_t> p = ranked(r);
    if (p.first >= match.best_cost()) break;
    if (p.second != bound_index) match.offer(p.second, filtered_cost(p.first, candidates, p.second, points, dim));
  }
}

void offer_ranked(RunningMatch& match, const float* points, int dim, const int64_t* rows, const float* sqdist,
                  int found, int64_t bound_index, const CandidateFilter* candidates) {
  offer_ranked(
      match, points, dim, found, [&](int r) { return std::pair<float, int64_t>(sqdist[r], rows[r]); }, bound_index,
      candidates);
}

int64_t rerank_shortlist(const float* points, int dim, const float* query, const int64_t* rows, const float* sqdist,
                         int found, int64_t bound_index, float* out_cost, float transition_cost,
                         const CandidateFilter* candidates) {
  RunningMatch match(points, dim, query, bound_index, transition_cost, candidates);
  offer_ranked(match, points, dim, rows, sqdist, found, bound_index, candidates);
  return match.finish(out_cost);
}

}  // namespace

int64_t brute_force_match_shortlist(const float* points, int64_t num_points, int dim, const uint8_t* valid,
                                    const float* query, int shortlist, int64_t exclude_lo, int64_t exclude_hi,
                                    int64_t bound_index, float* out_cost, float transition_cost,
                                    const CandidateFilter* candidates, int num_queries, int other_shortlist,
                                    const int32_t* extra_rows, int num_extra) {
  check_points(points, num_points, dim, "brute_force_match_shortlist");
  if (query == nullptr) throw std::invalid_argument("brute_force_match_shortlist: null query");
  if (bound_index >= num_points) throw std::out_of_range("brute_force_match_shortlist: bound_index out of range");
  check_shortlist(shortlist, transition_cost, num_queries, other_shortlist, "brute_force_match_shortlist");
  check_extra(extra_rows, num_extra, num_points, "brute_force_match_shortlist");
  int64_t rows[kMaxShortlist * (kMaxShortlistQueries + 1)];
  float sqdist[kMaxShortlist * (kMaxShortlistQueries + 1)];
  int found[kMaxShortlistQueries + 1];
  SearchFilter filter;
  filter.allowed = valid;
  filter.exclude_lo = exclude_lo;
  filter.exclude_hi = exclude_hi;
  for (int q = 0; q < num_queries; ++q)
    found[q] = brute_force_knn(points, num_points, dim, query + static_cast<size_t>(q) * dim,
                               q == 0 ? shortlist : other_shortlist, rows + q * kMaxShortlist,
                               sqdist + q * kMaxShortlist, filter);
  int lists = num_queries;
  if (num_extra > 0) {  // the extra rows as one more list
    found[lists] = 0;
    for (int r = 0; r < num_extra; ++r)
      if (extra_rows[r] >= 0 && is_allowed(extra_rows[r], filter))
        rows[lists * kMaxShortlist + found[lists]++] = extra_rows[r];
    ++lists;
  }
  const int n = lists == 1 ? found[0] : merge_shortlists(points, dim, query, rows, sqdist, found, lists, kMaxShortlist);
  return rerank_shortlist(points, dim, query, rows, sqdist, n, bound_index, out_cost, transition_cost, candidates);
}

Matcher::Matcher(const float* rows, int64_t num_rows, int dim, const uint8_t* valid, const MatcherOptions& options)
    : rows_(rows),
      valid_(valid),
      tree_([&] {
        check_points(rows, num_rows, dim, "Matcher");
        if (options.leaf_size < 1) throw std::invalid_argument("Matcher: leaf_size must be >= 1");
        int64_t num_valid = 0;
        for (int64_t i = 0; i < num_rows; ++i) num_valid += (!valid || valid[i]) ? 1 : 0;
        // Tiny databases: a tree cannot prune enough to pay for itself; one leaf is a
        // plain blocked scan with early termination.
        const bool scan = num_valid < options.brute_force_below;
        const int leaf = scan ? static_cast<int>(std::max<int64_t>(1, num_valid)) : options.leaf_size;
        return KDTree(rows, num_rows, dim, leaf, valid);
      }()) {}

MMRL_MULTIVERSION int64_t Matcher::match(const float* query, int64_t exclude_lo, int64_t exclude_hi, int64_t bound_index,
                       float* out_cost, float transition_cost, const CandidateFilter* candidates) const {
  SearchFilter filter;
  filter.exclude_lo = exclude_lo;
  filter.exclude_hi = exclude_hi;
  filter.candidates = candidates;
  return tree_.nearest_with_bound(query, bound_index, out_cost, filter, transition_cost);
}

int64_t Matcher::match_shortlist(const float* query, int shortlist, int64_t exclude_lo, int64_t exclude_hi,
                                 int64_t bound_index, float* out_cost, float transition_cost,
                                 const CandidateFilter* candidates, int num_queries, int other_shortlist,
                                 const int32_t* extra_rows, int num_extra) const {
  check_shortlist(shortlist, transition_cost, num_queries, other_shortlist, "Matcher::match_shortlist");
  if (bound_index >= tree_.size()) throw std::out_of_range("Matcher::match_shortlist: bound_index out of range");
  check_extra(extra_rows, num_extra, tree_.size(), "Matcher::match_shortlist");
  int64_t rows[kMaxShortlist * kMaxShortlistQueries];
  float sqdist[kMaxShortlist * kMaxShortlistQueries];
  int found[kMaxShortlistQueries];
  SearchFilter filter;
  filter.exclude_lo = exclude_lo;
  filter.exclude_hi = exclude_hi;
  const int dim = tree_.dim();
  found[0] = kdtree_knn(tree_, query, shortlist, rows, sqdist, filter);
  RunningMatch match(rows_, dim, query, bound_index, transition_cost, candidates);
  offer_ranked(match, rows_, dim, rows, sqdist, found[0], bound_index, candidates);
  // The other queries' rows and the extra rows lie outside the first query's `shortlist`
  // nearest, so no nearer than its last: a winner strictly cheaper than that distance stands
  // whatever they hold, and when the first query found fewer rows it found them all. Otherwise
  // their new rows, ranked by distance to the first query, go on where its own left off
  // (re-ranking the union, with no row priced twice).
  if ((num_queries == 1 && num_extra == 0) || found[0] < shortlist || match.best_cost() < sqdist[found[0] - 1])
    return match.finish(out_cost);
  for (int q = 1; q < num_queries; ++q)
    found[q] = kdtree_knn(tree_, query + static_cast<size_t>(q) * dim, other_shortlist, rows + q * kMaxShortlist,
                          sqdist + q * kMaxShortlist, filter);
  std::sort(rows, rows + found[0]);  // the first query's rows, to leave out of the rest
  std::pair<float, int64_t> more[kMaxShortlist * kMaxShortlistQueries + kMaxExtraRows];
  int n = 0;
  const auto add = [&](int64_t i) {
    if (!std::binary_search(rows, rows + found[0], i)) more[n++] = {sqdist_row(query, rows_ + i * dim, dim), i};
  };
  for (int q = 1; q < num_queries; ++q)
    for (int r = 0; r < found[q]; ++r) add(rows[q * kMaxShortlist + r]);
  SearchFilter returnable = filter;  // the extra rows the search itself could return (as the brute force)
  returnable.allowed = valid_;
  for (int r = 0; r < num_extra; ++r)
    if (extra_rows[r] >= 0 && is_allowed(extra_rows[r], returnable)) add(extra_rows[r]);
  std::sort(more, more + n);
  n = static_cast<int>(std::unique(more, more + n) - more);
  offer_ranked(match, rows_, dim, n, [&](int r) { return more[r]; }, bound_index, candidates);
  return match.finish(out_cost);
}

namespace {

template <class One>
void run_batch(const char* who, const float* queries, int64_t num_queries, int64_t num_rows, int dim, int64_t* out_indices,
               float* out_costs, ThreadPool& pool, const int64_t* exclude_lo, const int64_t* exclude_hi,
               const int64_t* bound_indices, One&& one) {
  if (num_queries < 0) throw std::invalid_argument(std::string(who) + ": num_queries must be >= 0");
  if (num_queries == 0) return;
  if (!queries || !out_indices || !out_costs) throw std::invalid_argument(std::string(who) + ": null pointer");
  if ((exclude_lo == nullptr) != (exclude_hi == nullptr))
    throw std::invalid_argument(std::string(who) + ": give both exclude_lo and exclude_hi, or neither");
  // Validate up front: nothing may throw inside the pool's workers.
  if (bound_indices)
    for (int64_t q = 0; q < num_queries; ++q)
      if (bound_indices[q] < -1 || bound_indices[q] >= num_rows)
        throw std::out_of_range(std::string(who) + ": bound index " + std::to_string(bound_indices[q]) +
                                " of query " + std::to_string(q) + " is outside [-1, " + std::to_string(num_rows) +
                                ")");
  pool.parallel_for(
      num_queries,
      [&](int64_t b, int64_t e, int) {
        for (int64_t q = b; q < e; ++q)
          out_indices[q] = one(queries + q * dim, exclude_lo ? exclude_lo[q] : 0, exclude_hi ? exclude_hi[q] : 0,
                               bound_indices ? bound_indices[q] : -1, out_costs + q);
      },
      /*min_chunk=*/4);
}

}  // namespace

void Matcher::match_batch(const float* queries, int64_t num_queries, int64_t* out_indices, float* out_costs,
                          ThreadPool& pool, const int64_t* exclude_lo, const int64_t* exclude_hi,
                          const int64_t* bound_indices) const {
  run_batch("Matcher::match_batch", queries, num_queries, num_rows(), dim(), out_indices, out_costs, pool, exclude_lo,
            exclude_hi, bound_indices, [this](const float* q, int64_t lo, int64_t hi, int64_t bound, float* cost) {
              return match(q, lo, hi, bound, cost);
            });
}

void Matcher::brute_force_batch(const float* queries, int64_t num_queries, int64_t* out_indices, float* out_costs,
                                ThreadPool& pool, const int64_t* exclude_lo, const int64_t* exclude_hi,
                                const int64_t* bound_indices) const {
  run_batch("Matcher::brute_force_batch", queries, num_queries, num_rows(), dim(), out_indices, out_costs, pool, exclude_lo,
            exclude_hi, bound_indices, [this](const float* q, int64_t lo, int64_t hi, int64_t bound, float* cost) {
              return brute_force_match(rows_, num_rows(), dim(), valid_, q, lo, hi, bound, cost);
            });
}

MMRL_MULTIVERSION int kdtree_knn(const KDTree& tree, const float* query, int k, int64_t* out_indices,
                                 float* out_sqdist, const SearchFilter& filter) {
  return tree.knn(query, k, out_indices, out_sqdist, filter);
}

MMRL_MULTIVERSION void kdtree_knn_batch(const KDTree& tree, const float* queries, int64_t num_queries, int k,
                                        int64_t* out_indices, float* out_sqdist, const SearchFilter& filter) {
  tree.knn_batch(queries, num_queries, k, out_indices, out_sqdist, filter);
}

void kdtree_knn_batch(const KDTree& tree, const float* queries, int64_t num_queries, int k, int64_t* out_indices,
                      float* out_sqdist, ThreadPool& pool, const SearchFilter& filter) {
  const char* who = "kdtree_knn_batch";
  if (num_queries < 0) throw std::invalid_argument(std::string(who) + ": num_queries must be >= 0");
  if (num_queries == 0) return;
  if (!queries || !out_indices || !out_sqdist) throw std::invalid_argument(std::string(who) + ": null pointer");
  const int64_t max_k = std::max<int64_t>(1, tree.indexed_size());
  if (k < 1 || k > max_k)
    throw std::invalid_argument(std::string(who) + ": k = " + std::to_string(k) + " is outside [1, " +
                                std::to_string(max_k) + "]");
  const int dim = tree.dim();
  pool.parallel_for(
      num_queries,
      [&](int64_t b, int64_t e, int) {
        kdtree_knn_batch(tree, queries + b * dim, e - b, k, out_indices + b * k, out_sqdist + b * k, filter);
      },
      /*min_chunk=*/16);
}

}  // namespace mmrl
