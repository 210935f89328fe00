// The parallel loop of the kernels, its cancellation, and the in-order
// combination of per-task results that keeps every sum independent of the
// thread count. No pybind11 here: kernels stay testable and timeable without
// Python.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <utility>
#include <vector>

namespace voxgi {

// Raised by a kernel when its `should_stop` callback says the user pressed
// Ctrl-C; the binding turns it into KeyboardInterrupt.
struct Interrupted : std::runtime_error {
    Interrupted() : std::runtime_error("interrupted") {}
};

// Called by kernels every few milliseconds of work, from the calling thread
// only (never from a worker thread). Returns true when the work must stop.
// The bindings implement it by taking the GIL briefly and calling
// PyErr_CheckSignals; C++ callers may pass an empty function.
using StopCheck = std::function<bool()>;

inline int resolve_threads(int threads) {
    if (threads > 0) return threads;
    unsigned hw = std::thread::hardware_concurrency();
    return hw == 0 ? 1 : static_cast<int>(hw);
}

// Run body(task, thread_index) for task in [0, n_tasks) on `threads`
// threads, handing out tasks dynamically. The calling thread is worker 0 and
// polls `stop` between its own tasks; once it returns true no new task is
// started and Interrupted is thrown after all workers have joined.
// Exceptions from workers are rethrown on the calling thread.
template <class Body>
void parallel_for(int64_t n_tasks, int threads, const StopCheck& stop, Body&& body) {
    threads = std::max(1, std::min<int>(threads, static_cast<int>(std::max<int64_t>(n_tasks, 1))));
    std::atomic<int64_t> next{0};
    std::atomic<bool> cancel{false};
    std::vector<std::exception_ptr> errors(threads);
    auto worker = [&](int t) {
        try {
            for (;;) {
                if (cancel.load(std::memory_order_relaxed)) return;
                if (t == 0 && stop && stop()) {
                    cancel = true;
                    return;
                }
                int64_t i = next.fetch_add(1);
                if (i >= n_tasks) return;
                body(i, t);
            }
        } catch (...) {
            errors[t] = std::current_exception();
            cancel = true;
        }
    };
    std::vector<std::thread> pool;
    for (int t = 1; t < threads; ++t) pool.emplace_back(worker, t);
    worker(0);
    for (auto& th : pool) th.join();
    for (auto& e : errors)
        if (e) std::rethrow_exception(e);
    if (cancel) throw Interrupted();  // only stop() can have set it without an error
}

// body(i) for every i < n, `chunk` consecutive items a task: neighbouring
// items (pixels of one row, records of nearby voxels) stay on one thread.
template <class Body>
void for_each_chunked(int64_t n, int64_t chunk, int threads, const StopCheck& stop, Body&& body) {
    const int64_t tasks = (n + chunk - 1) / chunk;
    parallel_for(tasks, resolve_threads(threads), stop, [&](int64_t task, int) {
        const int64_t end = std::min(n, (task + 1) * chunk);
        for (int64_t i = task * chunk; i < end; ++i) body(i);
    });
}

// The sum over tasks of body(begin, end), each task `chunk` consecutive
// items [begin, end) (an item count: rays traced, say): each task adds to
// the shared sum once, where a per-item atomic add would make the cores
// pass its cache line between them item by item.
template <class Body>
int64_t sum_over_chunks(int64_t n, int64_t chunk, int threads, const StopCheck& stop, Body&& body) {
    const int64_t tasks = (n + chunk - 1) / chunk;
    std::atomic<int64_t> total{0};
    parallel_for(tasks, resolve_threads(threads), stop, [&](int64_t task, int) {
        const int64_t begin = task * chunk;
        total.fetch_add(body(begin, std::min(n, begin + chunk)), std::memory_order_relaxed);
    });
    return total.load();
}

// The sum over i < n of body(i), `chunk` consecutive items a task.
template <class Body>
int64_t sum_chunked(int64_t n, int64_t chunk, int threads, const StopCheck& stop, Body&& body) {
    return sum_over_chunks(n, chunk, threads, stop, [&](int64_t begin, int64_t end) {
        int64_t s = 0;
        for (int64_t i = begin; i < end; ++i) s += body(i);
        return s;
    });
}

// Hands the results of tasks 0, 1, 2, ... to `combine` in task order,
// whichever order the tasks finish in: floating-point sums made from
// per-task partials then come out the same for any number of threads.
// Results that finish early wait here (moved in, not copied); `combine`
// runs under the lock, one result at a time.
template <class Result>
class InOrder {
   public:
    template <class Combine>
    void finish(int64_t task, Result&& r, Combine&& combine) {
        std::lock_guard<std::mutex> lock(mu_);
        waiting_.emplace(task, std::move(r));
        for (auto it = waiting_.begin(); it != waiting_.end() && it->first == next_;) {
            combine(it->second);
            it = waiting_.erase(it);
            ++next_;
        }
    }

   private:
    std::mutex mu_;
    int64_t next_ = 0;
    std::map<int64_t, Result> waiting_;
};

}  // namespace voxgi
