// What the CaT-GS cache tests of both backends (tests/test_catgs.cpp, tests/gpu/
// test_cuda_catgs.cpp) run over camera paths: the accuracy bar and the cache configurations
// it holds for, the stripe test's flight and configurations, and (CPU) the check that a cached
// frame lacks no pair. Each backend keeps its own list of paths: the CPU renders fewer pixels
// and adds scripted turns and climbs, the GPU renders a denser city.
#pragma once

#include <cstddef>
#include <cstdint>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "catgs/camera.hpp"
#include "catgs/render_options.hpp"
#include "catgs/scene.hpp"
#include "catgs/trajectory.hpp"

namespace catgs::test {

/// The bar cached and split frames are held to against the per-frame full render: PSNR on
/// average over a path and on its worst frame.
inline constexpr double kMeanPsnrBar = 45.0, kWorstPsnrBar = 40.0;

/// A named camera path.
struct CameraPath {
    std::string name;
    std::vector<Camera> cameras;
};

/// One configuration a path runs under; `label` is appended to the path's name in the log.
struct CacheRun {
    std::string label;
    RenderOptions options;
};

/// The configurations the bar holds for, each with k = 64 so that cached frames carry split
/// tasks too (the default k and auto k are too large for lists this short: the combination a
/// sweep once found broken): the defaults (default_pipeline_options: adaptive window, the key
/// frame's depth order reused), that cache with W fixed at 4 so that fast paths also run on
/// speculated poses, and W = 4 with cached frames re-sorted (exact order).
inline std::vector<CacheRun> accuracy_bar_runs() {
    RenderOptions defaults = default_pipeline_options();
    defaults.catgs.split_k = 64;
    // The window chosen from work counts, not wall time, so that every run plans alike.
    defaults.catgs.window_cost = WindowCost::work;
    RenderOptions fixed = defaults;
    fixed.catgs.adaptive_window = false;
    fixed.catgs.window = 4;
    RenderOptions resorted = fixed;
    resorted.catgs.resort_cached = true;
    return {{" defaults", defaults}, {" W=4", fixed}, {" W=4 re-sorted", resorted}};
}

/// Calls `run(path, cache_run)` for every path under every run of the accuracy bar.
template <typename Run>
void for_each_accuracy_bar_run(const std::vector<CameraPath>& paths, Run run) {
    for (const CameraPath& p : paths)
        for (const CacheRun& r : accuracy_bar_runs()) run(p, r);
}

/// The stripe artifacts of the paper's Figure 7 need a low, pitched, fast flight: reused
/// lists then miss Gaussians that moved into new tiles unless the cache speculates.
inline constexpr const char* kStripesPath = "builtin:flythrough?frames=24&altitude=35&pitch=-30&speed=14";
/// Without speculation the worst frame of that flight falls below this: the stripes show.
inline constexpr double kStripedWorstPsnr = 35.0;

/// kStripesPath over `city` through `run_path(scene, cameras, options)`, with the cache over a
/// fixed window of 6 frames: first without speculation, then with it.
template <typename RunPath>
auto run_stripes_path(const Scene& city, const Intrinsics& k, RunPath run_path) {
    const std::vector<Camera> cameras = make_trajectory(kStripesPath, city.bounds, k);
    RenderOptions unspeculated;
    unspeculated.catgs.cache = CacheMode::unspeculated;
    unspeculated.catgs.window = 6;
    unspeculated.catgs.adaptive_window = false;
    RenderOptions speculative = unspeculated;
    speculative.catgs.cache = CacheMode::speculative;
    auto without = run_path(city, cameras, unspeculated);
    auto with = run_path(city, cameras, speculative);
    return std::pair{without, with};
}

/// Every Gaussian the full per-frame pipeline puts in a tile must be in the cached list of
/// that tile (CPU renderers of any precision). Returns the number of (tile, Gaussian) pairs
/// missing.
template <typename Renderer>
std::uint64_t missing_pairs(const Renderer& cached, const Renderer& full) {
    std::uint64_t missing = 0;
    const auto& cr = cached.tile_ranges();
    const auto& fr = full.tile_ranges();
    for (std::size_t t = 0; t < fr.size(); ++t) {
        std::set<std::uint32_t> have(cached.sorted_values().begin() + static_cast<std::ptrdiff_t>(cr[t].begin),
                                     cached.sorted_values().begin() + static_cast<std::ptrdiff_t>(cr[t].end));
        for (std::uint64_t j = fr[t].begin; j < fr[t].end; ++j) missing += !have.count(full.sorted_values()[j]);
    }
    return missing;
}

}  // namespace catgs::test
