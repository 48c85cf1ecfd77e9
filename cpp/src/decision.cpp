#include "mmrl/decision.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <thread>

namespace mmrl {

void check_frames_per_step(int frames_per_step) {
  if (frames_per_step < 1 || frames_per_step > kMaxFramesPerStep)
    throw std::invalid_argument("frames_per_step must be between 1 and " + std::to_string(kMaxFramesPerStep) +
                                ", got " + std::to_string(frames_per_step));
}

ClipCostFilter::ClipCostFilter(const Database& db, std::vector<float> costs, const char* option)
    : costs_(std::move(costs)) {
  if (costs_.empty()) return;
  if (static_cast<int64_t>(costs_.size()) != db.num_clips())
    throw std::invalid_argument(std::string(option) + ": expected one cost per clip (" +
                                std::to_string(db.num_clips()) + "), got " + std::to_string(costs_.size()));
  for (size_t c = 0; c < costs_.size(); ++c)
    if (!(costs_[c] >= 0.0f))
      throw std::invalid_argument(std::string(option) + ": the cost of clip " + std::to_string(c) +
                                  " must be >= 0 (inf: never play it), got " + std::to_string(costs_[c]));
  frame_clip_ = db.frame_clip.data();
}

int shortlist_queries(const Database& db, const float* query, const Shortlist& shortlist, float* out) {
  std::copy(query, query + kFeatureDim, out);
  float raw[kTrajectoryDim], turned[kTrajectoryDim];
  trajectory_denormalize(db, query + kPoseDim, raw);
  int n = 1;
  for (int m = 1; m <= shortlist.fan; ++m)
    for (int side : {1, -1}) {
      const float a = static_cast<float>(side * m) * shortlist.fan_step;
      const float c = std::cos(a), s = std::sin(a);
      for (int k = 0; k < kTrajectoryDim; k += 2) {  // (x, z) pairs: positions and directions
        turned[k] = c * raw[k] + s * raw[k + 1];
        turned[k + 1] = -s * raw[k] + c * raw[k + 1];
      }
      float* q = out + static_cast<size_t>(n) * kFeatureDim;
      std::copy(query, query + kPoseDim, q);
      trajectory_normalize(db, turned, q + kPoseDim);
      ++n;
    }
  return n;
}

void escape_trajectory(const Database& db, int e, float* raw) {
  if (e < 0 || e >= kMaxEscapes) throw std::out_of_range("escape_trajectory: no escape " + std::to_string(e));
  // Stand, back, left, right (X left, Z forward) facing ahead; then walks towards 0, +-45,
  // +-90, +-135, 180 degrees (positive: to the left) facing the way they go; then runs.
  static constexpr float kSteps[4][2] = {{0, 0}, {0, -1}, {1, 0}, {-1, 0}};
  static constexpr float kWalkDegrees[8] = {0, 45, -45, 90, -90, 135, -135, 180};
  float dx, dz, fx = 0.0f, fz = 1.0f, speed = kEscapeSpeed;
  if (e < 4) {
    dx = kSteps[e][0], dz = kSteps[e][1];
  } else {
    const float a = kWalkDegrees[(e - 4) % 8] * 3.14159265358979f / 180.0f;
    dx = fx = std::sin(a), dz = fz = std::cos(a);
    speed = e < 12 ? kEscapeWalkSpeed : 2.0f * kEscapeWalkSpeed;
  }
  for (int h = 0; h < 3; ++h) {
    const float d = speed * static_cast<float>(kTrajectoryOffsets[h]) / db.fps;
    raw[4 * h] = dx * d;
    raw[4 * h + 1] = dz * d;
    raw[4 * h + 2] = fx;
    raw[4 * h + 3] = fz;
  }
}

namespace {

void check_escape_counts(int escapes, int k) {
  if (escapes < 1 || escapes > kMaxEscapes || k < 1 || escapes * k > kMaxExtraRows)
    throw std::invalid_argument("EscapeTable: escapes must be in [1, " + std::to_string(kMaxEscapes) +
                                "] and k >= 1 with escapes * k <= " + std::to_string(kMaxExtraRows) + ", got " +
                                std::to_string(escapes) + " and " + std::to_string(k));
}

}  // namespace

EscapeTable::EscapeTable(int64_t num_frames, int escapes, int k, std::vector<int32_t> rows)
    : row_count_((check_escape_counts(escapes, k), escapes * k)), rows_(std::move(rows)) {
  if (rows_.size() != static_cast<size_t>(num_frames) * row_count_)
    throw std::invalid_argument("escape table: " + std::to_string(rows_.size()) + " entries, not " +
                                std::to_string(num_frames) + " frames x " + std::to_string(row_count_));
  for (size_t i = 0; i < rows_.size(); ++i)
    if (rows_[i] < -1 || rows_[i] >= num_frames)
      throw std::invalid_argument("escape table: entry " + std::to_string(i) + " (" + std::to_string(rows_[i]) +
                                  ") is not a frame of the database or -1");
}

EscapeTable::EscapeTable(const Database& db, const Matcher& matcher, int escapes, int k, int threads)
    : row_count_(escapes * k) {
  check_escape_counts(escapes, k);
  if (matcher.num_rows() != db.num_frames) throw std::invalid_argument("EscapeTable: the matcher is not over db");
  float trajectories[kMaxEscapes][kTrajectoryDim];
  for (int e = 0; e < escapes; ++e) {
    float raw[kTrajectoryDim];
    escape_trajectory(db, e, raw);
    trajectory_normalize(db, raw, trajectories[e]);
  }
  rows_.assign(static_cast<size_t>(db.num_frames) * row_count_, -1);
  if (matcher.num_valid() == 0) return;
  ThreadPool pool(std::max(1, threads));
  pool.parallel_for(
      db.num_frames,
      [&](int64_t b, int64_t end, int) {
        float query[kFeatureDim], sqdist[kMaxExtraRows];
        int64_t found[kMaxExtraRows];
        for (int64_t f = b; f < end; ++f) {
          SearchFilter filter;  // decision_match's exclusion window of frame f
          const int c = db.frame_clip[f];
          filter.exclude_lo = std::max<int64_t>(db.clip_ranges[c * 2], f - kMatchExcludeWindow);
          filter.exclude_hi = std::min<int64_t>(db.clip_ranges[c * 2 + 1], f + kMatchExcludeWindow + 1);
          for (int e = 0; e < escapes; ++e) {
            decision_query(db, f, trajectories[e], query);
            const int n = kdtree_knn(matcher.tree(), query, std::min<int64_t>(k, matcher.num_valid()), found, sqdist,
                                     filter);
            int32_t* out = &rows_[static_cast<size_t>(f) * row_count_ + static_cast<size_t>(e) * k];
            for (int r = 0; r < n; ++r) out[r] = static_cast<int32_t>(found[r]);
          }
        }
      },
      /*min_chunk=*/256);
}

std::shared_ptr<const EscapeTable> EscapeTable::shared(const Database& db, const Matcher& matcher, int escapes, int k,
                                                       std::shared_ptr<const EscapeTable> prebuilt) {
  return matcher.cached<EscapeTable>("escapes " + std::to_string(escapes) + " " + std::to_string(k), [&] {
    if (prebuilt) return prebuilt;
    const unsigned hw = std::thread::hardware_concurrency();
    return std::make_shared<const EscapeTable>(db, matcher, escapes, k, hw == 0 ? 1 : static_cast<int>(hw));
  });
}

void trajectory_action_box(const Database& db, float limit_std, float* low, float* high) {
  double sum[kTrajectoryDim] = {}, sq[kTrajectoryDim] = {};
  int64_t n = 0;
  for (int64_t i = 0; i < db.num_frames; ++i) {
    if (!db.valid[i]) continue;
    const float* t = &db.normalized[static_cast<size_t>(i) * kFeatureDim + kPoseDim];
    for (int k = 0; k < kTrajectoryDim; ++k) {
      sum[k] += t[k];
      sq[k] += static_cast<double>(t[k]) * t[k];
    }
    ++n;
  }
  for (int k = 0; k < kTrajectoryDim; ++k) {
    const double mean = n ? sum[k] / n : 0.0;
    const double sd = n ? std::sqrt(std::max(0.0, sq[k] / n - mean * mean)) : 1.0;
    low[k] = static_cast<float>(mean - limit_std * sd);
    high[k] = static_cast<float>(mean + limit_std * sd);
  }
}

}  // namespace mmrl
