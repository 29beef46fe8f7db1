#include "catgs/split_choice.hpp"

#include <algorithm>

#include "catgs/render_options.hpp"
#include "catgs/stage.hpp"

namespace catgs {

std::uint32_t SplitChooser::rung_k(int rung) const {
    if (base_auto_ || base_k_ == 0 || rung < 0 || rung >= kSplitLadderRungs) return 0;
    const std::uint64_t k =
        rung < kBaseRung ? std::uint64_t{base_k_} >> (kBaseRung - rung) : std::uint64_t{base_k_} << (rung - kBaseRung);
    return k >= 1 && k <= kMaxSplitK ? static_cast<std::uint32_t>(k) : 0;
}

int SplitChooser::rung_to_probe() {
    // Saturates: while no neighbour is due it stays at the bound (a stream may run for days).
    since_rung_probe_ = std::min(since_rung_probe_ + 1, kSplitRungProbeEvery);
    if (since_rung_probe_ < kSplitRungProbeEvery) return -1;
    const CostEstimate& chosen = rungs_[rung_];
    for (int tries = 0; tries < 2; ++tries) {
        const int rung = rung_ + (probe_up_ ? 1 : -1);
        probe_up_ = !probe_up_;
        if (rung_k(rung) == 0) continue;
        const CostEstimate& e = rungs_[rung];
        const bool clearly_dearer = e.known() && e.value() > kSplitRungClearMargin * chosen.value();
        if (clearly_dearer && decisions_ - e.last_frame() < static_cast<std::uint64_t>(kSplitClearProbeEvery)) continue;
        since_rung_probe_ = 0;
        return rung;
    }
    return -1;  // none due: the next frame asks again
}

bool SplitChooser::choose(const CatgsOptions& options) {
    if (!options.split_auto && options.split_k == 0) return false;
    if (options.split_k != base_k_ || options.split_auto != base_auto_) {
        reset();
        base_k_ = options.split_k;
        base_auto_ = options.split_auto;
    }
    measured_ = options.window_cost == WindowCost::time;
    probing_ = exploring_ = false;
    chosen_rung_ = kBaseRung;
    if (!measured_) return true;
    chosen_rung_ = rung_;
    ++decisions_;
    const CostEstimate& split = rungs_[rung_];
    if (!split.known() || !whole_.known()) {
        exploring_ = true;
        return !split.known();
    }
    const bool split_cheaper = split.value() <= whole_.value();
    const double loser = split_cheaper ? whole_.value() : split.value();
    const double winner = split_cheaper ? split.value() : whole_.value();
    const int every = loser > kSplitClearMargin * winner ? kSplitClearProbeEvery : kSplitProbeEvery;
    probing_ = exploring_ = ++since_probe_ >= every;
    if (probing_) {
        since_probe_ = 0;
        return !split_cheaper;
    }
    if (!split_cheaper) return false;
    if (const int rung = rung_to_probe(); rung >= 0) {
        chosen_rung_ = rung;
        probing_ = exploring_ = true;
    }
    return true;
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
    const double per_pair = ms * 1e6 / static_cast<double>(pairs);
    const double weight = probing_ ? kSplitProbeWeight : kSplitCostWeight;
    if (!split) {
        whole_.add(per_pair, decisions_, weight);
        return;
    }
    CostEstimate& rung = rungs_[chosen_rung_];
    rung.add(per_pair, decisions_, weight);
    // A probed rung that drew cheaper than the chosen one's estimate takes its place.
    if (chosen_rung_ != rung_ && rungs_[rung_].known() && rung.value() < rungs_[rung_].value()) rung_ = chosen_rung_;
}

}  // namespace catgs
