#include "catgs/host_copier.hpp"

#include <algorithm>
#include <cstring>
#include <system_error>

namespace catgs {

HostCopier::HostCopier(int helpers) : helpers_wanted_(std::max(helpers, 0)) {}

HostCopier::~HostCopier() {
    wait();
    {
        std::lock_guard lock(mutex_);
        stopping_ = true;
    }
    queued_.notify_all();
    for (std::thread& t : helpers_) t.join();
}

void HostCopier::start_helpers() {
    helpers_.reserve(static_cast<std::size_t>(helpers_wanted_));
    try {
        while (static_cast<int>(helpers_.size()) < helpers_wanted_) helpers_.emplace_back([this] { helper_loop(); });
    } catch (const std::system_error&) {
        helpers_wanted_ = static_cast<int>(helpers_.size());  // the caller and those that started do the work
    }
}

void HostCopier::copy(void* target, const void* source, std::size_t bytes) {
    if (bytes == 0) return;
    if (helpers_.size() < static_cast<std::size_t>(helpers_wanted_)) start_helpers();
    {
        std::lock_guard lock(mutex_);
        for (std::size_t at = 0; at < bytes; at += kPieceBytes)
            pieces_.push_back(Piece{static_cast<unsigned char*>(target) + at,
                                    static_cast<const unsigned char*>(source) + at, std::min(kPieceBytes, bytes - at)});
    }
    queued_.notify_all();
}

bool HostCopier::copy_one(std::unique_lock<std::mutex>& lock) {
    if (pieces_.empty()) return false;
    const Piece piece = pieces_.front();
    pieces_.pop_front();
    ++in_flight_;
    lock.unlock();
    std::memcpy(piece.target, piece.source, piece.bytes);
    lock.lock();
    if (--in_flight_ == 0 && pieces_.empty()) finished_.notify_all();
    return true;
}

void HostCopier::wait() {
    std::unique_lock lock(mutex_);
    while (copy_one(lock)) {
    }
    finished_.wait(lock, [this] { return pieces_.empty() && in_flight_ == 0; });
}

void HostCopier::helper_loop() {
    std::unique_lock lock(mutex_);
    for (;;) {
        queued_.wait(lock, [this] { return stopping_ || !pieces_.empty(); });
        if (stopping_ && pieces_.empty()) return;
        copy_one(lock);
    }
}

}  // namespace catgs
