// HostCopier (host_copier.hpp): the CUDA renderer's take of a large image out of its pinned
// staging, spread over helper threads. Checked here on random bytes, where a lost, repeated or
// misplaced piece shows.
#include <gtest/gtest.h>

#include <cstdint>
#include <random>
#include <stdexcept>
#include <vector>

#include "catgs/host_copier.hpp"
#include "test_util.hpp"

namespace catgs {
namespace {

std::vector<std::uint8_t> random_bytes(std::mt19937_64& rng, std::size_t n) {
    std::vector<std::uint8_t> v(n);
    for (auto& b : v) b = static_cast<std::uint8_t>(rng());
    return v;
}

/// Bands of random lengths (pieces cut short, lengths below and across kPieceBytes), queued
/// one after another into one image as the renderer does, then waited for once.
void expect_bands_copied(int helpers, std::uint64_t seed) {
    std::mt19937_64 rng(seed);
    const std::size_t piece = HostCopier::kPieceBytes;
    const std::vector<std::size_t> bands = {0, 1, piece - 1, piece, piece + 1, 3 * piece + 17, 5, 2 * piece};
    std::size_t total = 0;
    for (std::size_t b : bands) total += b;
    const std::vector<std::uint8_t> source = random_bytes(rng, total);
    std::vector<std::uint8_t> target = random_bytes(rng, total);  // stale bytes a missed piece would leave
    HostCopier copier(helpers);
    std::size_t at = 0;
    for (std::size_t b : bands) {
        copier.copy(target.data() + at, source.data() + at, b);
        at += b;
    }
    copier.wait();
    EXPECT_EQ(copier.helpers_started(), helpers);
    ASSERT_EQ(target.size(), source.size());
    for (std::size_t i = 0; i < total; ++i)
        ASSERT_EQ(target[i], source[i]) << "byte " << i << " of " << total << ", " << helpers << " helpers";
}

TEST(HostCopier, CopiesEveryBandWithAnyNumberOfHelpers) {
    const std::uint64_t seed = test::fresh_seed("host copier bands");
    for (int helpers : {0, 1, 3, 8}) expect_bands_copied(helpers, seed + static_cast<std::uint64_t>(helpers));
}

/// A renderer takes frame after frame through one copier: each wait covers its frame only,
/// and a frame's bytes never land in another's.
TEST(HostCopier, FramesThroughOneCopierStayApart) {
    std::mt19937_64 rng(test::fresh_seed("host copier frames"));
    HostCopier copier(3);
    for (int frame = 0; frame < 20; ++frame) {
        const std::size_t n = 1 + rng() % (4 * HostCopier::kPieceBytes);
        const std::vector<std::uint8_t> source = random_bytes(rng, n);
        std::vector<std::uint8_t> target(n, 0);
        const std::size_t half = n / 2;
        copier.copy(target.data(), source.data(), half);
        copier.copy(target.data() + half, source.data() + half, n - half);
        copier.wait();
        EXPECT_EQ(target, source) << "frame " << frame << ", " << n << " bytes";
    }
    copier.wait();  // nothing queued: returns at once
}

/// The guard waits as an exception leaves its scope, before the target is freed.
TEST(HostCopier, GuardWaitsWhenAnExceptionUnwinds) {
    std::mt19937_64 rng(test::fresh_seed("host copier guard"));
    const std::vector<std::uint8_t> source = random_bytes(rng, 6 * HostCopier::kPieceBytes + 3);
    std::vector<std::uint8_t> target(source.size(), 0);
    HostCopier copier(2);
    try {
        HostCopiesDone done(copier);
        copier.copy(target.data(), source.data(), source.size());
        throw std::runtime_error("a CUDA call failed");
    } catch (const std::runtime_error& e) {
        EXPECT_STREQ(e.what(), "a CUDA call failed");
        EXPECT_EQ(target, source) << "the copy must be complete once the guard is gone";
    }
}

/// A copier destroyed with copies queued finishes them first.
TEST(HostCopier, DestructionFinishesQueuedCopies) {
    std::mt19937_64 rng(test::fresh_seed("host copier destruction"));
    const std::vector<std::uint8_t> source = random_bytes(rng, 9 * HostCopier::kPieceBytes);
    std::vector<std::uint8_t> target(source.size(), 0);
    {
        HostCopier copier(3);
        copier.copy(target.data(), source.data(), source.size());
    }
    EXPECT_EQ(target, source);
}

}  // namespace
}  // namespace catgs
