// Which tiles a projected Gaussian touches: its tile rectangle, the exact ellipse-tile test,
// and the one predicate that the count pass and the emit pass both call
// (for_each_window_tile), so they can never disagree (graphdeco's NaN crash,
// gaussian-splatting#781, came from count and emit using different predicates).
#pragma once

#include <cstdint>

#include "catgs/constants.hpp"
#include "catgs/hd.hpp"
#include "catgs/math.hpp"
#include "catgs/stages/culling.hpp"
#include "catgs/stages/footprint.hpp"
#include "catgs/stages/project.hpp"
#include "catgs/stages/view.hpp"

namespace catgs {

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
        rects[k] =
            (valid >> k & 1u) ? tile_rect(poses[k], mode, view.tiles_x, view.tiles_y, guard) : TileRect{0, 0, 0, 0};
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
            for (int k = 0; k < window && !hit; ++k)
                hit = footprint_in_tile(poses[k], mode, rects[k], tx, ty, view, guard);
            if (!hit) continue;
            emit(static_cast<std::uint32_t>(ty * view.tiles_x + tx));
            ++n;
        }
    return n;
}

/// The single-frame predicate: the tiles one projected Gaussian touches under `mode`.
template <typename T, typename Emit>
CATGS_HD std::uint32_t for_each_touched_tile(const Projected<T>& g, Culling mode, const View<T>& view, Emit&& emit,
                                             TileRows rows = {}) {
    return for_each_window_tile<1>(&g, 1u, 1, mode, T(0), view, emit, rows);
}

}  // namespace catgs
