// Stage 2, which tiles a projected Gaussian touches. The count pass and the emit pass both
// call for_each_touched_tile, so they can never disagree (graphdeco's NaN crash,
// gaussian-splatting#781, came from count and emit using different predicates).
#pragma once

#include <cstdint>
#include <cstring>

#include "catgs/constants.hpp"
#include "catgs/hd.hpp"
#include "catgs/math.hpp"
#include "catgs/stages/project.hpp"
#include "catgs/stages/view.hpp"

namespace catgs {

enum class Culling : int {
    /// Every visible Gaussian is evaluated at every pixel: one list serves all tiles.
    /// The ground truth for tests; cost grows with Gaussians x pixels.
    exact = 0,
    /// graphdeco's square of tiles around the 3-sigma circle of the major axis.
    bbox3sigma = 1,
    /// The ellipse where sigma * exp(-q/2) reaches 1/255 (FlashGS, gsplat), with an exact
    /// ellipse-tile test: it drops only pairs whose every pixel has alpha < 1/255.
    opacity_aware = 2,
};

/// Relative and absolute slack on the opacity-aware level set, so that rounding in the
/// rasterizer's alpha can never make a pixel visible that the tile test rejected.
inline constexpr double kOpacityLevelRelativeSlack = 1e-3;
inline constexpr double kOpacityLevelAbsoluteSlack = 1e-3;

/// [x0, x1) x [y0, y1) in tiles.
struct TileRect {
    int x0, y0, x1, y1;
    CATGS_HD bool empty() const { return x0 >= x1 || y0 >= y1; }
};

/// floor(v) clamped to [lo, hi]; NaN maps to lo. Avoids the undefined float-to-int conversion
/// of values outside int range (huge Gaussians, far off-screen).
template <typename T>
CATGS_HD int clamped_floor(T v, int lo, int hi) {
    if (!(v > static_cast<T>(lo))) return lo;
    if (!(v < static_cast<T>(hi))) return hi;
    return static_cast<int>(floor_of(v));
}

/// The squared Mahalanobis level q (conic form) inside which alpha >= 1/255:
/// sigma * exp(-q/2) >= 1/255  <=>  q <= 2 ln(255 sigma). Negative when sigma < 1/255.
template <typename T>
CATGS_HD T opacity_level(T opacity) {
    const T level = T(2) * log_of(opacity / static_cast<T>(kMinAlpha));
    return level * static_cast<T>(1.0 + kOpacityLevelRelativeSlack) + static_cast<T>(kOpacityLevelAbsoluteSlack);
}

/// Half extents (pixels, x and y) of a footprint: graphdeco's 3-sigma radius of the major
/// axis (both axes) for bbox3sigma, the axis-aligned box of the ellipse q <= level for
/// opacity-aware culling, negative when the Gaussian cannot reach alpha 1/255 anywhere.
template <typename T>
CATGS_HD Vec2<T> footprint_extent(const Projected<T>& g, Culling mode) {
    if (mode == Culling::bbox3sigma) {
        const T mid = T(0.5) * (g.cov.x + g.cov.z);
        const T det = g.cov.x * g.cov.z - g.cov.y * g.cov.y;
        const T spread = mid * mid - det;
        const T floor_spread = static_cast<T>(kBBoxEigenFloor);
        const T lambda = mid + sqrt_of(spread > floor_spread ? spread : floor_spread);
        const T radius = ceil_of(static_cast<T>(kBBoxSigmas) * sqrt_of(lambda));
        return {radius, radius};
    }
    const T level = opacity_level(g.opacity);
    if (!(level > T(0))) return {T(-1), T(-1)};
    // Axis-aligned half extents of the ellipse q <= level: sqrt(level * Sigma'_ii).
    return {sqrt_of(level * g.cov.x), sqrt_of(level * g.cov.z)};
}

/// The axis-aligned box [x0, x1] x [y0, y1] (pixels) of the opacity-aware ellipse, slack
/// included: outside it alpha < 1/255, which blending draws as nothing. A rasterizer may
/// therefore skip a Gaussian for a whole block of pixels whose centres miss the box, with the
/// same guarantee as opacity-aware tile culling. Empty when alpha cannot reach 1/255.
template <typename T>
struct PixelBox {
    T x0, y0, x1, y1;
};

template <typename T>
CATGS_HD PixelBox<T> visible_box(const Projected<T>& g) {
    const Vec2<T> e = footprint_extent(g, Culling::opacity_aware);
    // Empty: a box beyond every pixel centre (3e38 is finite in float and double).
    if (e.x < T(0)) return {T(3e38), T(3e38), T(-3e38), T(-3e38)};
    return {g.mean.x - e.x, g.mean.y - e.y, g.mean.x + e.x, g.mean.y + e.y};
}

/// Do the pixel centres [cx0, cx1] x [cy0, cy1] all miss the box? NaN bounds miss nothing,
/// so a Gaussian whose extent is not finite is never skipped.
template <typename T>
CATGS_HD bool box_misses_centres(const PixelBox<T>& b, T cx0, T cy0, T cx1, T cy1) {
    return b.x0 > cx1 || b.x1 < cx0 || b.y0 > cy1 || b.y1 < cy0;
}

/// An upper bound (pixels) on a footprint's half-extent at any pose near the current one: the
/// Gaussian's largest 3D scale projected at its depth, times the culling mode's sigma
/// multiple, plus the blur. Unlike the current 2D extent it does not vanish for a needle
/// seen end-on, whose footprint grows fast as the view turns; the cache envelope uses it.
template <typename T>
CATGS_HD T footprint_bound_px(const Projected<T>& g, Culling mode, T max_scale, T focal) {
    const T level = opacity_level(g.opacity);
    const T sigmas = mode == Culling::bbox3sigma ? static_cast<T>(kBBoxSigmas) : sqrt_of(level > T(0) ? level : T(0));
    return sigmas * (focal * max_scale / g.depth + sqrt_of(static_cast<T>(kCovarianceBlur)));
}

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
    T tangent = key.clamp_left > key.clamp_right ? key.clamp_left : key.clamp_right;
    tangent = key.clamp_top > tangent ? key.clamp_top : tangent;
    tangent = key.clamp_bottom > tangent ? key.clamp_bottom : tangent;
    const T kappa = T(1) + tangent * tangent;
    const T w = static_cast<T>(key.width), h = static_cast<T>(key.height), z = g.depth;
    // Beyond the clamp region (the image plus 15% of its size per side) a point is too far
    // off-axis to come in within the envelope, and first order no longer holds.
    if (!(g.mean.x >= T(-0.15) * w && g.mean.x <= T(1.15) * w && g.mean.y >= T(-0.15) * h && g.mean.y <= T(1.15) * h))
        return false;
    bound = footprint_bound_px(g, mode, max_scale, focal);
    const T reach = guard * (T(1) + bound / focal) + focal * kappa * guard_translation / z + bound * (T(1) + guard_translation / z);
    T away = -g.mean.x > g.mean.x - w ? -g.mean.x : g.mean.x - w;
    away = -g.mean.y > away ? -g.mean.y : away;
    away = g.mean.y - h > away ? g.mean.y - h : away;
    return away <= reach;
}

/// Tile rectangle of a Gaussian under a culling mode (exact mode: the whole grid), with the
/// footprint dilated by `guard` pixels (speculative windows; 0 for a single frame).
template <typename T>
CATGS_HD TileRect tile_rect(const Projected<T>& g, Culling mode, int tiles_x, int tiles_y, T guard = T(0)) {
    const T tile = static_cast<T>(kTileSize);
    if (mode == Culling::exact) return {0, 0, tiles_x, tiles_y};
    const Vec2<T> extent = footprint_extent(g, mode);
    if (mode == Culling::bbox3sigma) {
        // graphdeco's rectangle around the mean in its pixel convention (pixel i at
        // coordinate i), i.e. our mean minus 0.5.
        const T radius = extent.x + guard;
        const T px = g.mean.x - T(0.5), py = g.mean.y - T(0.5);
        return {clamped_floor((px - radius) / tile, 0, tiles_x), clamped_floor((py - radius) / tile, 0, tiles_y),
                clamped_floor((px + radius + tile - T(1)) / tile, 0, tiles_x),
                clamped_floor((py + radius + tile - T(1)) / tile, 0, tiles_y)};
    }
    if (!(extent.x >= T(0))) return {0, 0, 0, 0};
    const T hx = extent.x + guard, hy = extent.y + guard;
    // Pixel i (sampled at i + 0.5) can be inside when mean - h <= i + 0.5 <= mean + h.
    const T lo_x = g.mean.x - hx - T(0.5), hi_x = g.mean.x + hx - T(0.5);
    const T lo_y = g.mean.y - hy - T(0.5), hi_y = g.mean.y + hy - T(0.5);
    return {clamped_floor(lo_x / tile, 0, tiles_x), clamped_floor(lo_y / tile, 0, tiles_y),
            clamped_floor(hi_x / tile + T(1), 0, tiles_x), clamped_floor(hi_y / tile + T(1), 0, tiles_y)};
}

/// q(d) = a dx^2 + 2 b dx dy + c dy^2 for the conic (a, b, c).
template <typename T>
CATGS_INLINE T conic_form(Vec3<T> conic, T dx, T dy) {
    return conic.x * dx * dx + T(2) * conic.y * dx * dy + conic.z * dy * dy;
}

/// Minimum of q over the segment where one offset is fixed (`fixed`) and the other runs over
/// [lo, hi]; `along_y` says which one runs. q is convex in the running offset, so the
/// minimum is at its stationary point clamped into the segment.
template <typename T>
CATGS_INLINE T min_conic_on_edge(Vec3<T> conic, T fixed, T lo, T hi, bool along_y) {
    const T a = along_y ? conic.z : conic.x;  // coefficient of the running offset squared
    T s = -conic.y * fixed / a;
    s = s < lo ? lo : (s > hi ? hi : s);
    return along_y ? conic_form(conic, fixed, s) : conic_form(conic, s, fixed);
}

/// Exact test: does the ellipse q <= level reach a pixel centre region of tile (tx, ty)?
/// The region is the rectangle spanned by the tile's pixel centres (clipped to the image),
/// grown by `guard` pixels on every side for speculative windows (a square dilation of the
/// ellipse, which contains the round one); q is minimised over it: zero if the mean is
/// inside, else on one of its four edges.
template <typename T>
CATGS_HD bool ellipse_touches_tile(const Projected<T>& g, T level, int tx, int ty, int width, int height,
                                   T guard = T(0)) {
    const int px0 = tx * kTileSize, py0 = ty * kTileSize;
    const int px1 = (px0 + kTileSize < width ? px0 + kTileSize : width) - 1;
    const int py1 = (py0 + kTileSize < height ? py0 + kTileSize : height) - 1;
    const T x0 = static_cast<T>(px0) + T(0.5) - guard - g.mean.x, x1 = static_cast<T>(px1) + T(0.5) + guard - g.mean.x;
    const T y0 = static_cast<T>(py0) + T(0.5) - guard - g.mean.y, y1 = static_cast<T>(py1) + T(0.5) + guard - g.mean.y;
    if (x0 <= T(0) && x1 >= T(0) && y0 <= T(0) && y1 >= T(0)) return true;
    T q = min_conic_on_edge(g.conic, x0, y0, y1, true);
    T e = min_conic_on_edge(g.conic, x1, y0, y1, true);
    q = e < q ? e : q;
    e = min_conic_on_edge(g.conic, y0, x0, x1, false);
    q = e < q ? e : q;
    e = min_conic_on_edge(g.conic, y1, x0, x1, false);
    q = e < q ? e : q;
    return q <= level;
}

/// Tile rows [begin, end): the GPU backend renders a frame whose tile-Gaussian pairs do not
/// fit its arena in horizontal bands; a band restricts the tiles a Gaussian touches.
struct TileRows {
    int begin = 0;
    int end = 1 << 30;
};

/// Is tile (tx, ty) in the footprint whose tile rectangle is `rect`? The per-tile half of
/// the predicate, also used on its own by cached frames to drop pairs the current pose no
/// longer needs.
template <typename T>
CATGS_HD bool footprint_in_tile(const Projected<T>& g, Culling mode, const TileRect& rect, int tx, int ty,
                                const View<T>& view, T guard = T(0)) {
    return tx >= rect.x0 && tx < rect.x1 && ty >= rect.y0 && ty < rect.y1 &&
           (mode != Culling::opacity_aware ||
            ellipse_touches_tile(g, opacity_level(g.opacity), tx, ty, view.width, view.height, guard));
}

/// Does a single-frame footprint touch tile `tile`? Exactly the tiles for_each_touched_tile
/// emits (exact mode: every tile).
template <typename T>
CATGS_HD bool touches_tile(const Projected<T>& g, Culling mode, const View<T>& view, std::uint32_t tile) {
    if (mode == Culling::exact) return true;
    const TileRect r = tile_rect(g, mode, view.tiles_x, view.tiles_y);
    return footprint_in_tile(g, mode, r, static_cast<int>(tile % view.tiles_x), static_cast<int>(tile / view.tiles_x),
                             view);
}

/// The tile predicate of count and emit. Calls emit(tile_id) for every tile in the union of
/// the footprints of the poses whose bit is set in `valid` (projections poses[0..window)),
/// each dilated by `guard` pixels, within `rows`; returns how many.
///
/// One pose with guard 0 is the single-frame case (for_each_touched_tile). Several poses are
/// CaT-GS's speculative multi-frame preprocessing: at a key frame each Gaussian is projected
/// against all W poses of the window and gets the union of its footprints, so the frames of
/// the window can reuse the sorted lists (see cache.hpp for the guard band's guarantee).
/// In exact mode each Gaussian emits one entry for tile 0: the tile-ranges stage then gives
/// that single list to every tile.
template <int MaxWindow, typename T, typename Emit>
CATGS_HD std::uint32_t for_each_window_tile(const Projected<T>* poses, std::uint32_t valid, int window, Culling mode,
                                            T guard, const View<T>& view, Emit&& emit, TileRows rows = {}) {
    if (valid == 0) return 0;
    if (mode == Culling::exact) {
        emit(std::uint32_t{0});
        return 1;
    }
    TileRect rects[MaxWindow];
    TileRect u{view.tiles_x, view.tiles_y, 0, 0};
    for (int k = 0; k < window; ++k) {
        rects[k] = (valid >> k & 1u) ? tile_rect(poses[k], mode, view.tiles_x, view.tiles_y, guard) : TileRect{0, 0, 0, 0};
        if (rects[k].empty()) continue;
        u.x0 = rects[k].x0 < u.x0 ? rects[k].x0 : u.x0;
        u.y0 = rects[k].y0 < u.y0 ? rects[k].y0 : u.y0;
        u.x1 = rects[k].x1 > u.x1 ? rects[k].x1 : u.x1;
        u.y1 = rects[k].y1 > u.y1 ? rects[k].y1 : u.y1;
    }
    u.y0 = u.y0 > rows.begin ? u.y0 : rows.begin;
    u.y1 = u.y1 < rows.end ? u.y1 : rows.end;
    if (u.empty()) return 0;
    std::uint32_t n = 0;
    for (int ty = u.y0; ty < u.y1; ++ty)
        for (int tx = u.x0; tx < u.x1; ++tx) {
            bool hit = false;
            for (int k = 0; k < window && !hit; ++k) hit = footprint_in_tile(poses[k], mode, rects[k], tx, ty, view, guard);
            if (!hit) continue;
            emit(static_cast<std::uint32_t>(ty * view.tiles_x + tx));
            ++n;
        }
    return n;
}

/// The first pose set in `valid` (not 0): the pose whose depth orders a Gaussian's keys.
CATGS_INLINE int first_valid_pose(std::uint32_t valid) {
    int k = 0;
    while (!(valid >> k & 1u)) ++k;
    return k;
}

/// The single-frame predicate: the tiles one projected Gaussian touches under `mode`.
template <typename T, typename Emit>
CATGS_HD std::uint32_t for_each_touched_tile(const Projected<T>& g, Culling mode, const View<T>& view, Emit&& emit,
                                             TileRows rows = {}) {
    return for_each_window_tile<1>(&g, 1u, 1, mode, T(0), view, emit, rows);
}

/// Sort key: tile id in the high 32 bits, the float bits of the view depth in the low 32.
/// Depth > near plane > 0, and positive IEEE floats order like their bit patterns.
CATGS_INLINE std::uint64_t make_sort_key(std::uint32_t tile, float depth) {
#if defined(__CUDA_ARCH__)
    const std::uint32_t bits = __float_as_uint(depth);
#else
    std::uint32_t bits;
    static_assert(sizeof(bits) == sizeof(depth));
    std::memcpy(&bits, &depth, sizeof(bits));
#endif
    return (static_cast<std::uint64_t>(tile) << 32) | bits;
}

CATGS_INLINE std::uint32_t key_tile(std::uint64_t key) { return static_cast<std::uint32_t>(key >> 32); }

/// Cached frames park the pairs the current pose does not need at tile id `tiles`: past every
/// real tile, so they sort last and no range covers them (bit_width(tiles) sort bits hold it).
CATGS_INLINE std::uint32_t parked_tile(std::uint32_t tiles) { return tiles; }

}  // namespace catgs
