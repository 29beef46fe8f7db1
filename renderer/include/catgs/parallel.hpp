// A minimal parallel-for for the CPU backend: `threads` workers pull fixed-size chunks of
// [0, n) from an atomic counter. Results never depend on the thread count, because every
// chunk writes only its own outputs.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <exception>
#include <mutex>
#include <system_error>
#include <thread>
#include <vector>

namespace catgs {

/// The most threads a flag may ask for: far above any host's cores (more only costs thread
/// starts), low enough that a typo such as 100000 is refused instead of starting that many.
inline constexpr int kMaxThreads = 1024;

inline int default_thread_count() {
    unsigned n = std::thread::hardware_concurrency();
    return n == 0 ? 1 : static_cast<int>(n);
}

/// Calls body(begin, end) over chunks of at most `grain` indices. The first exception thrown
/// by a worker is rethrown on the calling thread after all workers have stopped.
template <typename Body>
void parallel_for(std::size_t n, std::size_t grain, int threads, Body&& body) {
    if (n == 0) return;
    grain = std::max<std::size_t>(grain, 1);
    const std::size_t chunks = (n + grain - 1) / grain;
    const int workers = static_cast<int>(std::min<std::size_t>(chunks, static_cast<std::size_t>(std::max(threads, 1))));
    std::atomic<std::size_t> next{0};
    std::exception_ptr failure;
    std::mutex failure_mutex;
    auto work = [&] {
        try {
            for (std::size_t c; (c = next.fetch_add(1)) < chunks;) body(c * grain, std::min(n, (c + 1) * grain));
        } catch (...) {
            std::lock_guard lock(failure_mutex);
            if (!failure) failure = std::current_exception();
            next = chunks;
        }
    };
    if (workers <= 1) {
        work();
    } else {
        std::vector<std::thread> pool;
        pool.reserve(static_cast<std::size_t>(workers - 1));
        // A host out of threads (ulimit -u, a container's pids limit) gets the work done by
        // those that started: the results do not depend on their number.
        try {
            for (int i = 1; i < workers; ++i) pool.emplace_back(work);
        } catch (const std::system_error&) {
        }
        work();
        for (auto& t : pool) t.join();
    }
    if (failure) std::rethrow_exception(failure);
}

}  // namespace catgs
