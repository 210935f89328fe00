// Shared plumbing for the voxgi kernels: cancellation, threads, errors.
// No pybind11 here: kernels stay testable and timeable without Python.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <functional>
#include <stdexcept>
#include <string>
#include <thread>
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
void parallel_for(int64_t n_tasks, int threads, const StopCheck &stop, Body &&body) {
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
    for (auto &th : pool) th.join();
    for (auto &e : errors)
        if (e) std::rethrow_exception(e);
    if (cancel) throw Interrupted();  // only stop() can have set it without an error
}

}  // namespace voxgi
