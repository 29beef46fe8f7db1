// The window of a key frame and what its preprocess tells the frame planner: the CPU
// backend's part of the inter-frame cache (cache.hpp), beside the pipeline in cpu_renderer.cpp.
#include <algorithm>
#include <cmath>

#include "catgs/cpu_renderer.hpp"
#include "catgs/stages/envelope.hpp"

namespace catgs {

// The window: every pose projected with the near plane lowered by the translation guard and
// footprints dilated by the pixel guard, so a pose inside the envelope finds every Gaussian it
// needs in the cached lists.
template <typename T>
typename CpuRenderer<T>::Window CpuRenderer<T>::key_window(const Scene& scene, const FramePlanner::Plan& plan,
                                                           const RenderOptions& options) const {
    Window window;
    const bool speculative = plan.cache(options.catgs) == CacheMode::speculative;
    window.guard = speculative ? static_cast<T>(options.catgs.guard_px) : T(0);
    window.guard_translation = speculative ? static_cast<T>(options.catgs.guard_translation) : T(0);
    const double near = plan.window_near_plane(options.catgs, options.near_plane);
    window.near_plane = static_cast<T>(near);
    for (const Camera& c : plan.poses) window.views.push_back(make_view<T>(c, scene.origin, near));
    return window;
}

// What the planner needs to bound screen motion: the nearest cached depth over the window's
// poses, the mean inverse depth at the key pose, and a bound on the footprints that do not
// already cover the whole grid (a full-grid footprint cannot gain tiles): the larger of the
// current 2D extent and the projected 3D size, which also covers needles seen end-on.
template <typename T>
KeyFrameSummary CpuRenderer<T>::summarize(const Scene& scene, const Window& window, Culling culling) const {
    KeyFrameSummary s;
    s.min_depth = window_min_depth_;
    double inverse_sum = 0;
    std::uint64_t visible = 0;
    const View<T>& key = window.views[0];
    for (std::size_t i = 0; i < projected_.size(); ++i) {
        if (tiles_touched_[i] == 0) continue;
        const Projected<T>& p = projected_[i];
        if (!(p.opacity > 0)) continue;
        ++visible;
        inverse_sum += 1.0 / static_cast<double>(p.depth);
        if (cached_can_gain_tiles(culling, tiles_touched_[i], key)) {
            const float* sc = &scene.scales[3 * i];
            const T bound = cached_extent_bound_px(p, culling, static_cast<T>(std::max({sc[0], sc[1], sc[2]})),
                                                   std::max(key.fx, key.fy));
            s.max_extent_px = std::max(s.max_extent_px, static_cast<double>(bound));
        }
    }
    s.max_extent_px = std::max(s.max_extent_px, uncached_bound_px_);
    s.mean_inverse_depth = visible ? inverse_sum / static_cast<double>(visible) : 0.0;
    if (!std::isfinite(s.min_depth)) s.min_depth = static_cast<double>(window.near_plane);
    s.min_depth = std::max(s.min_depth, static_cast<double>(window.near_plane));
    return s;
}

// The class is instantiated in cpu_renderer.cpp; these are its members defined here.
template typename CpuRenderer<float>::Window CpuRenderer<float>::key_window(const Scene&, const FramePlanner::Plan&,
                                                                            const RenderOptions&) const;
template typename CpuRenderer<double>::Window CpuRenderer<double>::key_window(const Scene&, const FramePlanner::Plan&,
                                                                              const RenderOptions&) const;
template KeyFrameSummary CpuRenderer<float>::summarize(const Scene&, const Window&, Culling) const;
template KeyFrameSummary CpuRenderer<double>::summarize(const Scene&, const Window&, Culling) const;

}  // namespace catgs
