// Whether a frame's task lists split their long tiles (CaT-GS Algorithm 1, stages/split.hpp),
// chosen from measured rasterize time.
//
// Why measured. Splitting a tile lets its sub-tasks run on several multiprocessors, but each
// later sub-task blends its whole slice from T = 1, not knowing that the pixels in front of it
// may already be opaque, and the merge costs its own pass. On the bench kit's garden at 1080p
// splitting at k = 8192 cut rasterize from 2.93 to 1.88 ms; at 4K, where the same scene spreads
// over four times the tiles, it raised it from 1.96 to 2.63 ms (H200, 2026-12-02). No rule on
// list lengths alone separated the two, so the choice is learned per path.
//
// The rule. Each side (split, whole) keeps an exponentially weighted average of rasterize +
// merge + copy_out milliseconds per million rendered pairs, which follows the content without
// mixing dense and sparse frames. copy_out counts because the GPU copies each band of tile rows
// while the rest is drawn, except where a split tile holds the band back until merge: on the
// kit's 4K paths split frames drew in about the same time as whole ones but exposed 0.29 ms
// more copy, and learned from rasterize + merge alone the chooser kept splitting (H200,
// 2026-12-04). A frame that builds task lists (a key frame, or a cached frame that
// re-sorts) splits while split is the cheaper side, or while either side is unmeasured (split
// first: it is what the options ask for). Every kSplitProbeEvery-th such frame renders the other
// side to keep its estimate fresh, which costs at most that share of the difference, and only
// every kSplitClearProbeEvery-th once the other side costs kSplitClearMargin more: on the kit's
// 4K paths the split probes were 1% of the path at one in 16, the larger half of what the
// defaults cost over plain frames there (H200, 2026-12-02). A probe
// moves its side's estimate more than an ordinary frame (kSplitProbeWeight), since that
// estimate has not been fed for a while.
//
// Which k. The k that draws fastest depends on the path, not only on the resolution: on the
// kit's garden at 1080p, k = 4096 drew the low path 4% faster than k = 8192 (path sums 0.785
// against 0.820 of plain frames) and the survey 1.6% slower (0.754 against 0.742), and 16384
// lost 20% and 11% (H100, session 40). So while splitting is the cheaper side, the k moves
// along a ladder of powers of two around the options' k (kSplitLadderBelow halvings,
// kSplitLadderAbove doublings), each rung with its own estimate: one list-building frame in
// kSplitRungProbeEvery tries the rung above or below the chosen one (in turn), and a probed
// rung that measures cheaper becomes the chosen one. A rung that costs kSplitRungClearMargin
// more is tried only every kSplitClearProbeEvery frames. With split_auto the frame's own mean
// list length sets k and there is no ladder.
//
// Only with CatgsOptions::window_cost = time: with work or off the frames must not depend on
// timing, and every frame splits at the options' k.
#pragma once

#include <array>
#include <cstdint>

#include "catgs/window_cost.hpp"

namespace catgs {

struct CatgsOptions;
struct FrameStats;

/// One frame in this many that build task lists renders the side not chosen...
inline constexpr int kSplitProbeEvery = 16;
/// ... and one in this many while the side not chosen costs this much more per pair.
inline constexpr int kSplitClearProbeEvery = 64;
inline constexpr double kSplitClearMargin = 1.25;
/// How much one frame moves a side's estimate.
inline constexpr double kSplitCostWeight = 0.25;
/// How much a probe moves the estimate of the side not chosen: that estimate is up to
/// kSplitProbeEvery frames old, so a probe weighs more, and two probes follow a change.
inline constexpr double kSplitProbeWeight = 0.5;
/// The ladder of k: the options' k halved up to kSplitLadderBelow times and doubled up to
/// kSplitLadderAbove times (k/8 .. 4k; rungs outside 1..kMaxSplitK are left out).
inline constexpr int kSplitLadderBelow = 3;
inline constexpr int kSplitLadderAbove = 2;
inline constexpr int kSplitLadderRungs = kSplitLadderBelow + 1 + kSplitLadderAbove;
/// While splitting is the cheaper side, one frame in this many that build task lists tries a
/// neighbouring rung, so each neighbour about one in twice this many. A neighbour within a few
/// percent costs that share of the difference; one clearly dearer waits longer (below).
inline constexpr int kSplitRungProbeEvery = 16;
/// A rung that costs this much more than the chosen one is tried only every
/// kSplitClearProbeEvery frames: on the kit's garden survey at 1080p the rung above k = 8192
/// costs 11% more, and trying it one frame in 32 would cost 0.3% of the path.
inline constexpr double kSplitRungClearMargin = 1.05;

class SplitChooser {
public:
    /// Whether the next frame that builds task lists may split (its long tiles still need to
    /// pass k). False when the options split nothing.
    bool choose(const CatgsOptions& options);
    /// The k of the last choice when it split: the options' k, or with window_cost = time the
    /// rung of the ladder chosen or probed; 0 with split_auto (the frame derives its own).
    std::uint32_t k() const { return rung_k(chosen_rung_); }
    /// What a frame that built its task lists with `split` (at k()) measured.
    void learn(bool split, const FrameStats& stats);
    void reset() { *this = SplitChooser{}; }
    /// The last choice explores: the first frame of its side or rung, or a probe. Its frame
    /// costs what the chooser would not have chosen, so the window cost model does not learn
    /// from it.
    bool exploring() const { return exploring_; }

    /// Milliseconds of rasterize + merge + copy_out per million pairs: splitting at the chosen
    /// rung, and whole (tests and tools).
    const CostEstimate& split_cost() const { return rungs_[rung_]; }
    const CostEstimate& whole_cost() const { return whole_; }
    /// The chosen rung's k (split_auto: 0).
    std::uint32_t chosen_k() const { return rung_k(rung_); }

private:
    static constexpr int kBaseRung = kSplitLadderBelow;
    /// The k of `rung` (0 where it leaves 1..kMaxSplitK, or with split_auto).
    std::uint32_t rung_k(int rung) const;
    /// A neighbouring rung due for a probe (-1: none), while splitting is the cheaper side.
    int rung_to_probe();

    std::array<CostEstimate, kSplitLadderRungs> rungs_;
    CostEstimate whole_;
    std::uint32_t base_k_ = 0;  // the options' k the ladder is built on
    bool base_auto_ = false;
    int rung_ = kBaseRung;         // the rung chosen as the cheapest
    int chosen_rung_ = kBaseRung;  // the rung of the last choice (a probe's may differ)
    std::uint64_t decisions_ = 0;
    int since_probe_ = 0;       // measured choices since the last probe of the other side
    int since_rung_probe_ = 0;  // measured split choices since the last rung probe
    bool probe_up_ = false;     // the next rung probe tries the rung above
    bool measured_ = false;     // the last choice came from timings (window_cost = time)
    bool probing_ = false;      // the last choice was a probe
    bool exploring_ = false;    // the last choice was a probe or its side's first frame
};

}  // namespace catgs
