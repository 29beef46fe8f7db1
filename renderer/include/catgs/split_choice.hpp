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
// Only with CatgsOptions::window_cost = time: with work or off the frames must not depend on
// timing, and every frame splits as the options say.
#pragma once

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

class SplitChooser {
public:
    /// Whether the next frame that builds task lists may split (its long tiles still need to
    /// pass k). False when the options split nothing.
    bool choose(const CatgsOptions& options);
    /// What a frame that built its task lists with `split` measured.
    void learn(bool split, const FrameStats& stats);
    void reset() { *this = SplitChooser{}; }
    /// The last choice explores: the first frame of its side, or a probe. Its frame costs what
    /// the chooser would not have chosen, so the window cost model does not learn from it.
    bool exploring() const { return exploring_; }

    /// Milliseconds of rasterize + merge per million pairs, per side (tests and tools).
    const CostEstimate& split_cost() const { return split_; }
    const CostEstimate& whole_cost() const { return whole_; }

private:
    CostEstimate split_, whole_;
    std::uint64_t decisions_ = 0;
    int since_probe_ = 0;     // measured choices since the last probe
    bool measured_ = false;   // the last choice came from timings (window_cost = time)
    bool probing_ = false;    // the last choice was a probe
    bool exploring_ = false;  // the last choice was a probe or its side's first frame
};

}  // namespace catgs
