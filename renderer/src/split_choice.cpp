#include "catgs/split_choice.hpp"

#include "catgs/render_options.hpp"
#include "catgs/stage.hpp"

namespace catgs {

bool SplitChooser::choose(const CatgsOptions& options) {
    if (!options.split_auto && options.split_k == 0) return false;
    measured_ = options.window_cost == WindowCost::time;
    probing_ = exploring_ = false;
    if (!measured_) return true;
    ++decisions_;
    if (!split_.known() || !whole_.known()) {
        exploring_ = true;
        return !split_.known();
    }
    const bool split_cheaper = split_.value() <= whole_.value();
    const double loser = split_cheaper ? whole_.value() : split_.value();
    const double winner = split_cheaper ? split_.value() : whole_.value();
    const int every = loser > kSplitClearMargin * winner ? kSplitClearProbeEvery : kSplitProbeEvery;
    probing_ = exploring_ = ++since_probe_ >= every;
    if (probing_) since_probe_ = 0;
    return split_cheaper != probing_;
}

void SplitChooser::learn(bool split, const FrameStats& stats) {
    // Per pair of the full lists: a frame under the occlusion cut draws the same tiles from
    // shorter lists (the pairs it left out lay behind every pixel's stop) in about the same time.
    const std::uint64_t pairs = stats.pairs + stats.occluded_pairs;
    if (!measured_ || pairs == 0) return;
    // copy_out too: whatever of the copy a frame's split tiles leave exposed counts against
    // splitting. (While merge ran after rasterize on the GPU, every band holding a split tile
    // waited for it; the CPU backend has no copy.)
    const double ms = stats.stage_ms[Stage::rasterize] + stats.stage_ms[Stage::merge] + stats.stage_ms[Stage::copy_out];
    if (!(ms > 0)) return;
    (split ? split_ : whole_)
        .add(ms * 1e6 / static_cast<double>(pairs), decisions_, probing_ ? kSplitProbeWeight : kSplitCostWeight);
}

}  // namespace catgs
