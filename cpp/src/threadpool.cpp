#include "mmrl/threadpool.hpp"

#include <algorithm>
#include <chrono>
#include <thread>

namespace mmrl {

namespace {

// Spins until done() or `micros` have passed; true if done() came true. Each turn yields the
// core (sched_yield): a spinning thread takes no time from another runnable thread (a second
// training on the same cores, torch's threads), and costs nothing when the core is idle.
template <class Done>
bool spin_until(Done&& done, int micros) {
  const auto until = std::chrono::steady_clock::now() + std::chrono::microseconds(micros);
  for (int k = 0;; ++k) {
    if (done()) return true;
    if ((k & 7) == 7 && std::chrono::steady_clock::now() >= until) return false;
    std::this_thread::yield();
  }
}

}  // namespace

ThreadPool::ThreadPool(int num_threads) {
  if (num_threads <= 0) num_threads = std::max(1u, std::thread::hardware_concurrency());
  for (int i = 1; i < num_threads; ++i) workers_.emplace_back([this, i] { worker_loop(i); });
}

ThreadPool::~ThreadPool() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  start_cv_.notify_all();
  for (auto& w : workers_) w.join();
}

void ThreadPool::run_chunks(int thread_index) {
  for (;;) {
    const int64_t b = next_.fetch_add(chunk_);
    if (b >= n_) break;
    job_(ctx_, b, std::min(n_, b + chunk_), thread_index);
  }
}

void ThreadPool::run(int64_t n, int64_t min_chunk, Job job, void* ctx) {
  if (n <= 0) return;
  std::lock_guard<std::mutex> run_lock(run_mutex_);
  const int64_t threads = num_threads();
  // A few chunks per thread balances uneven work (some queries prune worse than others).
  int64_t chunk = std::max<int64_t>(min_chunk, (n + threads * 4 - 1) / (threads * 4));
  if (workers_.empty() || n <= min_chunk) {
    job(ctx, 0, n, 0);
    return;
  }
  {
    std::lock_guard<std::mutex> lock(mutex_);
    job_ = job;
    ctx_ = ctx;
    n_ = n;
    chunk_ = chunk;
    next_.store(0);
    pending_.store(static_cast<int>(workers_.size()));
    generation_.fetch_add(1);
  }
  start_cv_.notify_all();
  run_chunks(0);
  if (spin_until([this] { return pending_.load() == 0; }, kSpinMicros)) return;
  std::unique_lock<std::mutex> lock(mutex_);
  done_cv_.wait(lock, [this] { return pending_.load() == 0; });
}

void ThreadPool::worker_loop(int index) {
  uint64_t seen = 0;
  for (;;) {
    // A spinning worker sees the new generation (and, through the mutex the job was written
    // under, the job); then it takes the mutex anyway, once, to read the job's fields safely.
    spin_until([&] { return generation_.load() != seen; }, kSpinMicros);
    {
      std::unique_lock<std::mutex> lock(mutex_);
      start_cv_.wait(lock, [&] { return stop_ || generation_.load() != seen; });
      if (stop_) return;
      seen = generation_.load();
    }
    run_chunks(index);
    if (pending_.fetch_sub(1) == 1) {
      std::lock_guard<std::mutex> lock(mutex_);  // the caller may be about to sleep on done_cv_
      done_cv_.notify_one();
    }
  }
}

}  // namespace mmrl
