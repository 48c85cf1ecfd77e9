// A small persistent thread pool for batched work over environments or queries.
// parallel_for splits [0, n) into contiguous chunks, runs them on the workers and the
// calling thread, and returns when all are done. Dispatch allocates nothing: the job is
// passed as a function pointer plus a context pointer.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <thread>
#include <vector>

namespace mmrl {

class ThreadPool {
 public:
  // num_threads counts the calling thread; 0 means std::thread::hardware_concurrency().
  explicit ThreadPool(int num_threads = 0);
  ~ThreadPool();
  ThreadPool(const ThreadPool&) = delete;
  ThreadPool& operator=(const ThreadPool&) = delete;

  int num_threads() const { return static_cast<int>(workers_.size()) + 1; }

  // Calls fn(begin, end, thread_index) over chunks of [0, n). thread_index < num_threads().
  template <class Fn>
  void parallel_for(int64_t n, Fn&& fn, int64_t min_chunk = 1) {
    auto trampoline = [](void* ctx, int64_t b, int64_t e, int t) { (*static_cast<Fn*>(ctx))(b, e, t); };
    run(n, min_chunk, trampoline, static_cast<void*>(&fn));
  }

 private:
  using Job = void (*)(void*, int64_t, int64_t, int);
  void run(int64_t n, int64_t min_chunk, Job job, void* ctx);
  void worker_loop(int index);
  void run_chunks(int thread_index);

  std::vector<std::thread> workers_;
  std::mutex mutex_;
  std::condition_variable start_cv_, done_cv_;
  // Jobs come in bursts (a batched env steps every few hundred microseconds, with 35-45 us of
  // Python between steps): a worker that finished one, and the caller waiting for the workers,
  // wait for up to kSpinMicros, yielding the core each turn, before sleeping on the condition
  // variables, which saves a wake-up (tens of microseconds on a loaded machine) per job; 50 us
  // was too short to catch most steps (bench/README.md). Written under mutex_; read without it
  // while waiting.
  static constexpr int kSpinMicros = 200;
  std::atomic<uint64_t> generation_{0};
  std::atomic<int> pending_{0};
  bool stop_ = false;
  // Current job.
  Job job_ = nullptr;
  void* ctx_ = nullptr;
  int64_t n_ = 0, chunk_ = 1;
  std::atomic<int64_t> next_{0};
  std::mutex run_mutex_;  // one parallel_for at a time per pool
};

}  // namespace mmrl
