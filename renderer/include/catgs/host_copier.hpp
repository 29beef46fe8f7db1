// Host-to-host copies spread over a few threads that live as long as the copier: the CUDA
// renderer's image leaves its pinned staging band by band as each band's copy lands, and one
// thread copying at ~12 GB/s, a third of the link's rate, finished a 4K frame's image ~1.5 ms
// after the GPU's last copy (H100, session 38).
#pragma once

#include <condition_variable>
#include <cstddef>
#include <deque>
#include <mutex>
#include <thread>
#include <vector>

namespace catgs {

class HostCopier {
public:
    /// Copies are cut into pieces of this many bytes (the last shorter): small enough that a
    /// 4K band (1.7 MB) spreads over every helper, large enough that a piece's hand-over, a
    /// few microseconds, stays a few percent of its copy (~20 us at 12 GB/s).
    static constexpr std::size_t kPieceBytes = 256 * 1024;

    /// `helpers` threads beside the caller, started at the first copy (0: the caller copies
    /// everything in wait()). A host out of threads gets its copies done by those that started.
    explicit HostCopier(int helpers);
    ~HostCopier();
    HostCopier(const HostCopier&) = delete;
    HostCopier& operator=(const HostCopier&) = delete;

    /// Queues a copy of `bytes` from `source` to `target` (disjoint from every queued copy's
    /// target); both must stay valid until wait() returns.
    void copy(void* target, const void* source, std::size_t bytes);
    /// Returns once every queued copy is done; the caller copies pieces meanwhile.
    void wait();
    /// The helper threads running; on the thread that calls copy() (for tests and logs).
    int helpers_started() const { return static_cast<int>(helpers_.size()); }

private:
    struct Piece {
        void* target;
        const void* source;
        std::size_t bytes;
    };
    void start_helpers();
    void helper_loop();
    /// Takes the next piece under `lock` and copies it without the lock; false when none is queued.
    bool copy_one(std::unique_lock<std::mutex>& lock);

    int helpers_wanted_;
    std::vector<std::thread> helpers_;
    std::mutex mutex_;
    std::condition_variable queued_, finished_;
    std::deque<Piece> pieces_;
    std::size_t in_flight_ = 0;
    bool stopping_ = false;
};

/// Waits for a copier's queued copies when it leaves scope, also through an exception: the
/// copies write into buffers the caller may free as the exception unwinds.
class HostCopiesDone {
public:
    explicit HostCopiesDone(HostCopier& copier) : copier_(copier) {}
    ~HostCopiesDone() { copier_.wait(); }
    HostCopiesDone(const HostCopiesDone&) = delete;
    HostCopiesDone& operator=(const HostCopiesDone&) = delete;

private:
    HostCopier& copier_;
};

}  // namespace catgs
