// The pose-rate limit of one stream (Limits::max_pose_rate): a token bucket. A client faster
// than the rate is not refused; the session reads its next message later, so that HTTP/2 flow
// control slows the client down.
#pragma once

#include <chrono>

namespace catgs::server {

class TokenBucket {
public:
    using Clock = std::chrono::steady_clock;

    /// `rate` tokens per second (not above 0: no limit). The bucket starts full and holds one
    /// second's worth (at least one token): a client may burst that much after a pause.
    TokenBucket(double rate, Clock::time_point now);

    /// Takes one token at `now` (times never go backwards); returns how long the next take
    /// must wait for a whole token: zero when one is left.
    Clock::duration take(Clock::time_point now);

private:
    double rate_;
    double capacity_;
    double tokens_;
    Clock::time_point refilled_;
};

}  // namespace catgs::server
