#include "catgs/server/token_bucket.hpp"

#include <algorithm>

namespace catgs::server {

TokenBucket::TokenBucket(double rate, Clock::time_point now)
    : rate_(rate), capacity_(std::max(1.0, rate)), tokens_(capacity_), refilled_(now) {}

TokenBucket::Clock::duration TokenBucket::take(Clock::time_point now) {
    if (!(rate_ > 0)) return Clock::duration::zero();
    tokens_ = std::min(capacity_, tokens_ + rate_ * std::chrono::duration<double>(now - refilled_).count());
    refilled_ = now;
    tokens_ -= 1;
    if (tokens_ >= 1) return Clock::duration::zero();
    return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>((1 - tokens_) / rate_));
}

}  // namespace catgs::server
