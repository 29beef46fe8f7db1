// The pose-rate limiter on a fake clock: time points are made by hand, so the test neither
// sleeps nor depends on the machine's speed.
#include <gtest/gtest.h>

#include "catgs/server/token_bucket.hpp"

namespace catgs::server {
namespace {

using namespace std::chrono_literals;
using Clock = TokenBucket::Clock;

/// A clock that moves only when told to.
struct FakeClock {
    Clock::time_point now{};
    Clock::time_point advance(Clock::duration by) { return now += by; }
};

TEST(TokenBucket, AFullBucketLetsOneSecondsWorthThroughThenPacesAtTheRate) {
    FakeClock clock;
    TokenBucket bucket(10, clock.now);
    // Ten tokens: the first nine takes leave at least one, the tenth leaves none, and the next
    // take has to wait a tenth of a second for a whole one.
    for (int i = 0; i < 9; ++i) EXPECT_EQ(bucket.take(clock.now), Clock::duration::zero()) << "take " << i;
    EXPECT_EQ(bucket.take(clock.now), 100ms);
    // Taking exactly when told: one token has come back, and is taken at once.
    for (int i = 0; i < 5; ++i) EXPECT_EQ(bucket.take(clock.advance(100ms)), 100ms) << "paced take " << i;
}

TEST(TokenBucket, TakingEarlyOwesTheRest) {
    FakeClock clock;
    TokenBucket bucket(10, clock.now);
    for (int i = 0; i < 10; ++i) bucket.take(clock.now);
    // 50 ms later half a token has come back: taking leaves -0.5, 150 ms from a whole one.
    EXPECT_EQ(bucket.take(clock.advance(50ms)), 150ms);
}

TEST(TokenBucket, RefillsUpToItsCapacityOnly) {
    FakeClock clock;
    TokenBucket bucket(4, clock.now);
    for (int i = 0; i < 4; ++i) bucket.take(clock.now);
    // An hour idle refills four tokens, not 14400.
    clock.advance(1h);
    for (int i = 0; i < 3; ++i) EXPECT_EQ(bucket.take(clock.now), Clock::duration::zero()) << "take " << i;
    EXPECT_EQ(bucket.take(clock.now), 250ms);
}

TEST(TokenBucket, ARateBelowOneStillHoldsOneToken) {
    FakeClock clock;
    TokenBucket bucket(0.5, clock.now);
    // One token: taken at once, and the next one comes back after two seconds.
    EXPECT_EQ(bucket.take(clock.now), 2s);
    EXPECT_EQ(bucket.take(clock.advance(2s)), 2s);
}

TEST(TokenBucket, ZeroOrNegativeRateMeansNoLimit) {
    for (double rate : {0.0, -1.0}) {
        FakeClock clock;
        TokenBucket bucket(rate, clock.now);
        for (int i = 0; i < 1000; ++i) EXPECT_EQ(bucket.take(clock.now), Clock::duration::zero());
    }
}

}  // namespace
}  // namespace catgs::server
