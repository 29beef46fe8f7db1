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
#include "catgs/stages/tiles.hpp"
#include "catgs/stages/view.hpp"

namespace catgs {

/// Beyond the Jacobian clamp region, where uncached_can_enter's first order no longer holds:
/// can the footprint of `g` (seen from `key`) reach the image once the camera has moved by
/// `guard_translation` metres and turned by `guard` pixels? In metres, as chunk_may_be_visible
/// asks it of a chunk: the footprint is a sphere of sigmas (largest scale + the blur's width at
/// its depth) about the mean; a translation moves it by at most guard_translation against the
/// view's planes, and the turn is covered by widening the image's side planes by `guard`
/// pixels (a turn the planner accepts moves no direction by more than guard / (f kappa)
/// radians, less than the widened planes' angle). A point near the camera moves far on screen:
/// 0.2 m of translation brings a Gaussian 0.5 m away in from 30 px past a 160 px wide image,
/// beyond the clamp region (CatgsEnvelopeTraps).
template <typename T>
CATGS_HD bool footprint_may_reach_image(const Projected<T>& g, Culling mode, const View<T>& key, T guard,
                                        T guard_translation, T max_scale) {
    // footprint_bound_px at the smaller focal length, in metres at the mean's depth.
    const T focal_min = key.fx < key.fy ? key.fx : key.fy;
    const T z = g.depth;
    const T reach = footprint_bound_px(g, mode, max_scale, focal_min) * z / focal_min + guard_translation;
    const T w = static_cast<T>(key.width), h = static_cast<T>(key.height);
    // A side plane x <= a z (a = its tangent) lies (x - a z) / sqrt(1 + a^2) from the point; with
    // x = (mean - c) z / f that is z (mean - edge) / sqrt(f^2 + (edge - c)^2), edge the widened
    // image side in pixels. Outside all of them by more than `reach`: it cannot come in.
    const auto beyond = [z](T past_edge_px, T f, T edge_from_centre_px) {
        return z * past_edge_px / sqrt_of(f * f + edge_from_centre_px * edge_from_centre_px);
    };
    const T right = beyond(g.mean.x - (w + guard), key.fx, w + guard - key.cx);
    const T left = beyond(-guard - g.mean.x, key.fx, key.cx + guard);
    const T bottom = beyond(g.mean.y - (h + guard), key.fy, h + guard - key.cy);
    const T top = beyond(-guard - g.mean.y, key.fy, key.cy + guard);
    // Written so that NaN keeps the Gaussian: the planner then bounds its motion.
    return !(right > reach || left > reach || bottom > reach || top > reach);
}

/// Speculative cache: can a Gaussian that is in no list at a pose of the window (`key`,
/// projected there as `g`) enter the image at a pose the envelope accepts near it? Such a pose
/// turns the view by at most `guard` pixels and moves the camera by at most
/// `guard_translation` metres, so the mean moves by at most guard + f kappa dt / z (first
/// order, inside the Jacobian clamp region) and the footprint grows by at most
/// b (dt / z + guard / f) towards footprint_bound_px b; beyond the clamp region
/// footprint_may_reach_image asks it in metres. When it can, the planner must bound its motion
/// too: `bound` receives b.
template <typename T>
CATGS_HD bool uncached_can_enter(const Projected<T>& g, Culling mode, const View<T>& key, T guard, T guard_translation,
                                 T max_scale, T& bound) {
    const T focal = key.fx > key.fy ? key.fx : key.fy;
    const T tangent = max_clamp_tangent(key);
    const T kappa = T(1) + tangent * tangent;
    const T w = static_cast<T>(key.width), h = static_cast<T>(key.height), z = g.depth;
    if (!in_clamp_region(key, g.mean)) {
        if (!footprint_may_reach_image(g, mode, key, guard, guard_translation, max_scale)) return false;
        bound = footprint_bound_px(g, mode, max_scale, focal);
        return true;
    }
    bound = footprint_bound_px(g, mode, max_scale, focal);
    const T reach =
        guard * (T(1) + bound / focal) + focal * kappa * guard_translation / z + bound * (T(1) + guard_translation / z);
    T away = -g.mean.x > g.mean.x - w ? -g.mean.x : g.mean.x - w;
    away = -g.mean.y > away ? -g.mean.y : away;
    away = g.mean.y - h > away ? g.mean.y - h : away;
    return away <= reach;
}

/// Speculative cache: can a Gaussian whose mean a pose of the window projects nowhere, being at
/// or behind that pose's near plane (`view`'s, already lowered by the translation guard), come
/// in front of the frame's near plane at a pose the envelope accepts near it? That pose's
/// camera is at most guard_translation away and turned by at most guard / f radians, which
/// moves the mean's depth by at most guard_translation + |p| guard / f: a mean further behind
/// the camera stays behind it. And that pose's near plane lies at most view.near_plane +
/// guard_translation ahead, so the mean must then lie within the clamp region's frustum cut
/// there, widened by the footprint's `reach` (metres; kChunkSigmas largest scales covers
/// every culling mode's): within (near + guard) sqrt(1 + tx^2 + ty^2) + sqrt(2) reach + guard
/// of this pose's camera. A Gaussian 2 cm behind a hovering camera came 0.22 m ahead of it
/// after a 0.24 m step back, in no list.
template <typename T>
CATGS_HD bool behind_near_can_enter(const float* position, const View<T>& view, T guard, T guard_translation, T reach) {
    const Vec3<T> p{static_cast<T>(position[0]), static_cast<T>(position[1]), static_cast<T>(position[2])};
    const Vec3<T> pc = view.rotation * p + view.translation;
    if (!(pc.z <= view.near_plane)) return false;  // projected there (uncached_can_enter asks it), or NaN
    const T distance = sqrt_of(dot(pc, pc));
    const T turn = guard / (view.fx > view.fy ? view.fx : view.fy);
    if (pc.z + guard_translation + distance * turn <= T(0)) return false;  // every near plane is ahead
    const T tx = view.clamp_left > view.clamp_right ? view.clamp_left : view.clamp_right;
    const T ty = view.clamp_top > view.clamp_bottom ? view.clamp_top : view.clamp_bottom;
    const T within = (view.near_plane + guard_translation) * sqrt_of(T(1) + tx * tx + ty * ty) +
                     T(1.4142135623730951) * reach + guard_translation;
    return distance <= within;
}

/// Key-frame summary of a Gaussian in no list, over the window's poses (`poses`, projected
/// where `valid` has their bit): a cached frame may lie near any of them. Where it is
/// projected and can enter (uncached_can_enter), `nearest` takes its depth and `bound` its
/// footprint bound; where its mean is behind the near plane but can come in front
/// (behind_near_can_enter), `nearest` takes the near plane's depth. The one loop of both
/// backends' preprocess.
template <int MaxWindow, typename T>
CATGS_HD void summarize_uncached(const Projected<T>* poses, std::uint32_t valid, int window, const View<T>* views,
                                 const float* position, Culling mode, T guard, T guard_translation, T max_scale,
                                 T& nearest, T& bound) {
    for (int k = 0; k < pose_loop_bound<MaxWindow>(window); ++k) {
        if (k >= window) continue;
        T pose_bound = T(0);
        if (valid >> k & 1u) {
            if (uncached_can_enter(poses[k], mode, views[k], guard, guard_translation, max_scale, pose_bound)) {
                nearest = poses[k].depth < nearest ? poses[k].depth : nearest;
                bound = pose_bound > bound ? pose_bound : bound;
            }
        } else if (behind_near_can_enter(position, views[k], guard, guard_translation,
                                         static_cast<T>(kChunkSigmas) * max_scale)) {
            nearest = views[k].near_plane < nearest ? views[k].near_plane : nearest;  // at the near plane
        }
    }
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
