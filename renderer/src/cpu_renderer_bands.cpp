// CpuRenderer over its pair budget: a frame whose tile-Gaussian pairs would not fit in memory
// (huge splats filling a 4K screen: 10^9 pairs and more) is rendered in horizontal bands of
// tile rows. Each band runs keys -> sort -> ranges -> split -> rasterize -> merge on its own
// rows; a tile's list is the same as in one pass, so the image is too. A banded frame starts
// no cached window (it keeps no whole-frame lists).
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <mutex>
#include <string>

#include "catgs/cpu_renderer.hpp"
#include "catgs/error.hpp"
#include "catgs/parallel.hpp"

namespace catgs {
namespace {

/// Bytes one pair costs the CPU renderer: key and value, their sort buffers, and the copy a
/// key frame keeps for re-sorting cached frames.
constexpr std::uint64_t kBytesPerPair = 3 * (sizeof(std::uint64_t) + sizeof(std::uint32_t));
/// Share of physical memory the automatic budget may take: several sessions of a server on
/// the CPU backend each hold a renderer, beside the scenes.
constexpr double kAutoPairMemoryShare = 0.125;
/// The budget when the host's memory cannot be read.
constexpr std::uint64_t kFallbackPairBudget = std::uint64_t{1} << 26;

constexpr std::size_t kGaussianGrain = 4096;

using Clock = std::chrono::steady_clock;
double elapsed_ms(Clock::time_point since) {
    return std::chrono::duration<double, std::milli>(Clock::now() - since).count();
}

}  // namespace

template <typename T>
std::uint64_t CpuRenderer<T>::pair_budget() const {
    if (limits_.max_pairs > 0) return limits_.max_pairs;
    const long pages = ::sysconf(_SC_PHYS_PAGES), page_bytes = ::sysconf(_SC_PAGE_SIZE);
    if (pages <= 0 || page_bytes <= 0) return kFallbackPairBudget;
    const double bytes = static_cast<double>(pages) * static_cast<double>(page_bytes);
    return std::max<std::uint64_t>(1, static_cast<std::uint64_t>(kAutoPairMemoryShare * bytes / kBytesPerPair));
}

// After preprocess: the pairs of one pass are the union tile counts.
template <typename T>
bool CpuRenderer<T>::needs_bands(Culling culling) const {
    std::uint64_t total = 0;
    for (std::uint32_t count : tiles_touched_) total += count;
    const std::uint64_t budget = pair_budget();
    if (total <= budget) return false;
    if (culling == Culling::exact)  // one shared list: rows cannot divide it
        throw Error("cpu renderer: exact culling needs " + std::to_string(total) +
                    " pairs, more than the pair budget of " + std::to_string(budget));
    return true;
}

// The pairs of each tile row (the same predicate keys emits with), then rows gathered greedily
// into bands of at most the budget.
template <typename T>
std::vector<TileRows> CpuRenderer<T>::plan_bands(const Scene& scene, const Window& window, Culling culling) const {
    const View<T>& view = window.views[0];
    const int w = static_cast<int>(window.views.size());
    std::vector<std::uint64_t> row_pairs(static_cast<std::size_t>(view.tiles_y), 0);
    std::mutex row_mutex;
    parallel_for(tiles_touched_.size(), kGaussianGrain, threads_, [&](std::size_t begin, std::size_t end) {
        std::vector<std::uint64_t> local(row_pairs.size(), 0);
        Projected<T> poses[kMaxWindow];
        for (std::size_t i = begin; i < end; ++i) {
            if (tiles_touched_[i] == 0) continue;
            const std::uint32_t valid = project_window(scene, i, window, poses);
            for_each_window_tile<kMaxWindow>(poses, valid, w, culling, window.guard, view,
                                             [&](std::uint32_t tile) { ++local[tile / view.tiles_x]; });
        }
        std::lock_guard lock(row_mutex);
        for (std::size_t r = 0; r < local.size(); ++r) row_pairs[r] += local[r];
    });
    const std::uint64_t budget = pair_budget();
    std::vector<TileRows> bands;
    std::uint64_t in_band = 0;
    for (int r = 0; r < view.tiles_y; ++r) {
        const std::uint64_t pairs = row_pairs[static_cast<std::size_t>(r)];
        if (pairs > budget)
            throw Error("cpu renderer: tile row " + std::to_string(r) + " needs " + std::to_string(pairs) +
                        " tile-Gaussian pairs, more than the pair budget of " + std::to_string(budget) +
                        "; lower the resolution or raise the budget");
        if (bands.empty() || in_band + pairs > budget) {
            bands.push_back({r, r + 1});
            in_band = 0;
        }
        bands.back().end = r + 1;
        in_band += pairs;
    }
    return bands;
}

template <typename T>
void CpuRenderer<T>::render_bands(const Scene& scene, const View<T>& view, const Window& window,
                                  const RenderOptions& options, const CatgsOptions& split_options,
                                  const FrameOutput& out, FrameStats& stats) {
    auto t = Clock::now();
    const std::vector<TileRows> bands = plan_bands(scene, window, options.culling);
    stats.stage_ms[Stage::keys] += elapsed_ms(t);  // the CPU backend folds scan into keys
    emitted_keys_.clear();
    emitted_values_.clear();
    std::uint64_t pairs = 0, split_tasks = 0, longest_list = 0;
    for (const TileRows& rows : bands) {
        band_ = rows;
        t = Clock::now();
        keys(scene, window, options.culling);
        stats.stage_ms[Stage::keys] += elapsed_ms(t);
        sort_and_schedule(view, options, split_options, stats);
        draw_tasks(view, options, out, stats);
        pairs += rendered_pairs_;
        split_tasks += split_tasks_;
        longest_list = std::max(longest_list, longest_list_);
    }
    band_ = TileRows{};
    rendered_pairs_ = pairs;
    split_tasks_ = split_tasks;
    longest_list_ = longest_list;
    stats.bands = static_cast<int>(bands.size());
    stats.pairs = pairs;
    stats.split_tasks = split_tasks;
    stats.longest_list = longest_list;
    stats.tasks = static_cast<std::uint64_t>(view.tiles_x) * static_cast<std::uint64_t>(view.tiles_y) + split_tasks;
}

// The class is instantiated in cpu_renderer.cpp; these are its members defined here.
#define CATGS_CPU_BAND_MEMBERS(T)                                                                                 \
    template std::uint64_t CpuRenderer<T>::pair_budget() const;                                                   \
    template bool CpuRenderer<T>::needs_bands(Culling) const;                                                     \
    template std::vector<TileRows> CpuRenderer<T>::plan_bands(const Scene&, const Window&, Culling) const;        \
    template void CpuRenderer<T>::render_bands(const Scene&, const View<T>&, const Window&, const RenderOptions&, \
                                               const CatgsOptions&, const FrameOutput&, FrameStats&);
CATGS_CPU_BAND_MEMBERS(float)
CATGS_CPU_BAND_MEMBERS(double)
#undef CATGS_CPU_BAND_MEMBERS

}  // namespace catgs
