// The speculative cache's envelope, per Gaussian: what a key frame reports so that the frame
// planner (cache.hpp) can bound screen motion over every Gaussian a cached frame may need,
// whether it is in the cached lists or not. Both backends reduce these per-Gaussian bounds
// into their KeyFrameSummary.
#pragma once

#include <cstdint>

#include "catgs/hd.hpp"
#include "catgs/math.hpp"
#include "catgs/stages/culling.hpp"
#include "catgs/stages/footprint.hpp"
#include "catgs/stages/project.hpp"
#include "catgs/stages/view.hpp"

namespace catgs {

/// Speculative cache: can a Gaussian that is in no list at the key pose `key` (projected there
/// as `g`) enter the image at a pose the envelope accepts? Such a pose turns the view by at
/// most `guard` pixels and moves the camera by at most `guard_translation` metres, so the mean
/// moves by at most guard + f kappa dt / z (first order, inside the Jacobian clamp region) and
/// the footprint grows by at most b (dt / z + guard / f) towards footprint_bound_px b. When it
/// can, the planner must bound its motion too: `bound` receives b.
template <typename T>
CATGS_HD bool uncached_can_enter(const Projected<T>& g, Culling mode, const View<T>& key, T guard, T guard_translation,
                                 T max_scale, T& bound) {
    const T focal = key.fx > key.fy ? key.fx : key.fy;
    const T tangent = max_clamp_tangent(key);
    const T kappa = T(1) + tangent * tangent;
    const T w = static_cast<T>(key.width), h = static_cast<T>(key.height), z = g.depth;
    // Beyond the clamp region a point is too far off-axis to come in within the envelope, and
    // first order no longer holds.
    if (!in_clamp_region(key, g.mean)) return false;
    bound = footprint_bound_px(g, mode, max_scale, focal);
    const T reach =
        guard * (T(1) + bound / focal) + focal * kappa * guard_translation / z + bound * (T(1) + guard_translation / z);
    T away = -g.mean.x > g.mean.x - w ? -g.mean.x : g.mean.x - w;
    away = -g.mean.y > away ? -g.mean.y : away;
    away = g.mean.y - h > away ? g.mean.y - h : away;
    return away <= reach;
}

/// Key-frame summary: can a cached Gaussian whose union footprint touches `tiles` tiles gain
/// tiles at another pose of the envelope? Only one already in every list cannot (exact
/// culling: the one shared list). A full-grid rectangle is not enough: opacity-aware lists hold
/// only the tiles the ellipse touches, e.g. the diagonal ones of a thin diagonal ellipse.
template <typename T>
CATGS_HD bool cached_can_gain_tiles(Culling mode, std::uint32_t tiles, const View<T>& key) {
    return mode != Culling::exact &&
           tiles < static_cast<std::uint32_t>(key.tiles_x) * static_cast<std::uint32_t>(key.tiles_y);
}

/// Key-frame summary: the half-extent (pixels) a cached Gaussian that can gain tiles, seen at
/// the key pose as `g`, contributes to KeyFrameSummary::max_extent_px: the larger of its current
/// 2D extent and footprint_bound_px, the projected 3D size that also covers needles seen
/// end-on. `max_scale` is its largest 3D scale and `focal` the key view's larger focal length.
template <typename T>
CATGS_HD T cached_extent_bound_px(const Projected<T>& g, Culling mode, T max_scale, T focal) {
    const Vec2<T> e = footprint_extent(g, mode);
    const T bound = footprint_bound_px(g, mode, max_scale, focal);
    const T larger = e.x > e.y ? e.x : e.y;
    return bound > larger ? bound : larger;
}

}  // namespace catgs
