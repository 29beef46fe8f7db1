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
#include "catgs/stages/keys.hpp"
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

/// The tiles [x0, x1) of one tile row that a footprint reaches, within its rectangle.
struct TileSpan {
    int x0, x1;
};

/// The opacity-aware ellipse q(d) <= level of one Gaussian, set up to give, row by row, the
/// tiles it reaches: the same tiles as ellipse_touches_tile on each tile of the row, found
/// without testing them one by one. The band of a tile row (its pixel centres' rows, grown by
/// the guard) cuts a convex piece from the ellipse whose x-extent is an interval, and a tile
/// of the row touches the ellipse exactly where its pixel-centre columns (grown by the guard)
/// meet that interval. The ends of the interval are the ellipse's boundary at the rows
/// nearest its leftmost and rightmost points: a few square roots per row instead of four edge
/// minimisations per tile, which made the tile test most of preprocess and keys at 4K.
///
/// Computed in double whatever T is: near the top and bottom of the ellipse the boundary is
/// the square root of a small difference, which float would round by a good part of a pixel.
/// The level's own slack (kOpacityLevelRelativeSlack) covers the float rasterizer's rounding.
template <typename T>
struct EllipseRows {
    double mean_x, mean_y, a, b, level, det, half_y, peak_dy;
    /// 1 / a: a row's two ends divide by a, and a double division is a long instruction sequence
    /// on the GPU, which keys and preprocess's count repeat for every tile row of every footprint.
    double inverse_a;
    bool usable;  // false: a conic that is not positive definite (the tile test decides)

    /// Unusable until assigned: what a window's array holds for a pose without a footprint.
    CATGS_HD EllipseRows()
        : mean_x(0), mean_y(0), a(0), b(0), level(0), det(0), half_y(0), peak_dy(0), inverse_a(0), usable(false) {}
    CATGS_HD EllipseRows(const Projected<T>& g, T level_t)
        : mean_x(static_cast<double>(g.mean.x)),
          mean_y(static_cast<double>(g.mean.y)),
          a(static_cast<double>(g.conic.x)),
          b(static_cast<double>(g.conic.y)),
          level(static_cast<double>(level_t)),
          det(0),
          half_y(0),
          peak_dy(0),
          inverse_a(0) {
        const double c = static_cast<double>(g.conic.z);
        det = a * c - b * b;
        usable = a > 0 && c > 0 && det > 0 && level > 0 && is_finite(a * c) && is_finite(level) && is_finite(mean_x) &&
                 is_finite(mean_y);
        if (!usable) return;
        half_y = sqrt_of(level * a / det);         // the ellipse's y half-extent
        peak_dy = b * sqrt_of(level / (det * c));  // the leftmost point's dy; the rightmost's is -peak_dy
        inverse_a = 1.0 / a;
        usable = is_finite(half_y) && is_finite(peak_dy) && is_finite(inverse_a);
    }

    /// The tiles of row ty within `rect` whose pixel-centre rectangle, grown by `guard`,
    /// meets the ellipse (clipped to the image as ellipse_touches_tile clips it).
    template <typename V>
    CATGS_HD TileSpan span(int ty, const TileRect& rect, const View<V>& view, double guard) const {
        const int py0 = ty * kTileSize, py1 = (py0 + kTileSize < view.height ? py0 + kTileSize : view.height) - 1;
        double y0 = py0 + 0.5 - guard - mean_y, y1 = py1 + 0.5 + guard - mean_y;
        y0 = y0 > -half_y ? y0 : -half_y;
        y1 = y1 < half_y ? y1 : half_y;
        if (!(y0 <= y1)) return {rect.x0, rect.x0};
        const double right_dy = -peak_dy < y0 ? y0 : (-peak_dy > y1 ? y1 : -peak_dy);
        const double left_dy = peak_dy < y0 ? y0 : (peak_dy > y1 ? y1 : peak_dy);
        const double right = mean_x + (-b * right_dy + root(right_dy)) * inverse_a + guard;
        const double left = mean_x + (-b * left_dy - root(left_dy)) * inverse_a - guard;
        // Tile tx's pixel-centre columns: [16 tx + 0.5, min(16 tx + 16, width) - 0.5].
        if (!(left <= view.width - 0.5)) return {rect.x0, rect.x0};
        const int first = -clamped_floor(-(left - (kTileSize - 0.5)) / kTileSize, -(1 << 30), 1 << 30);
        const int last = clamped_floor((right - 0.5) / kTileSize, -(1 << 30), 1 << 30);
        const int x0 = first > rect.x0 ? first : rect.x0, x1 = last + 1 < rect.x1 ? last + 1 : rect.x1;
        return x0 < x1 ? TileSpan{x0, x1} : TileSpan{rect.x0, rect.x0};
    }

private:
    /// a * (the ellipse's half-width at row offset dy): sqrt(a level - det dy^2), 0 at its top and bottom.
    CATGS_HD double root(double dy) const {
        const double r = level * a - det * dy * dy;
        return r > 0 ? sqrt_of(r) : 0.0;
    }
};

/// The tiles of row ty that a footprint with tile rectangle `rect` touches under `mode`.
template <typename T>
CATGS_HD TileSpan footprint_row(const Projected<T>& g, Culling mode, const TileRect& rect, int ty, const View<T>& view,
                                T guard, const EllipseRows<T>& rows) {
    if (ty < rect.y0 || ty >= rect.y1) return {rect.x0, rect.x0};
    if (mode != Culling::opacity_aware) return {rect.x0, rect.x1};
    if (rows.usable) return rows.span(ty, rect, view, static_cast<double>(guard));
    // A conic that is not positive definite: ask each tile (rare; NaN reaches no tile).
    const T level = opacity_level(g.opacity);
    int x0 = rect.x1, x1 = rect.x0;
    for (int tx = rect.x0; tx < rect.x1; ++tx)
        if (ellipse_touches_tile(g, level, tx, ty, view.width, view.height, guard)) {
            x0 = tx < x0 ? tx : x0;
            x1 = tx + 1;
        }
    return x0 < x1 ? TileSpan{x0, x1} : TileSpan{rect.x0, rect.x0};
}

/// Which tiles a single-frame footprint touches, asked tile by tile: exactly the tiles
/// for_each_touched_tile emits (exact mode: every tile), through the same row spans. The
/// rectangle and the ellipse are set up once, and a row's span is kept for the next question:
/// a cached frame's re-key asks about a key frame's pairs, which come row by row, so each row's
/// span (two double square roots) is computed once, not once a tile.
template <typename T>
class TouchedTiles {
public:
    CATGS_HD TouchedTiles(const Projected<T>& g, Culling mode, const View<T>& view)
        : g_(g), view_(view), mode_(mode), rect_{0, 0, 0, 0}, row_(-1), span_{0, 0} {
        if (mode == Culling::exact) return;
        rect_ = tile_rect(g, mode, view.tiles_x, view.tiles_y);
        if (mode == Culling::opacity_aware && !rect_.empty()) rows_ = EllipseRows<T>(g, opacity_level(g.opacity));
    }

    CATGS_HD bool touches(std::uint32_t tile) {
        if (mode_ == Culling::exact) return true;
        const int tx = static_cast<int>(tile % view_.tiles_x), ty = static_cast<int>(tile / view_.tiles_x);
        if (tx < rect_.x0 || tx >= rect_.x1 || ty < rect_.y0 || ty >= rect_.y1) return false;
        if (ty != row_) {
            span_ = footprint_row(g_, mode_, rect_, ty, view_, T(0), rows_);
            row_ = ty;
        }
        return tx >= span_.x0 && tx < span_.x1;
    }

private:
    const Projected<T>& g_;
    const View<T>& view_;
    Culling mode_;
    TileRect rect_;
    EllipseRows<T> rows_;
    int row_;  // the row span_ belongs to (-1: none yet)
    TileSpan span_;
};

/// A cached frame's re-key of one Gaussian's pairs, the same on both backends: a pair the key
/// frame emitted keeps its tile while the footprint at the current pose touches it (the
/// single-frame predicate) and is parked past the grid otherwise, as are all the pairs of a
/// Gaussian culled at this pose. Exact culling shares one list among all tiles: nothing to
/// filter. Ask about the pairs in their emission order (row by row): TouchedTiles keeps a row.
template <typename T>
class RekeyedTiles {
public:
    CATGS_HD RekeyedTiles(const Projected<T>& g, Culling mode, const View<T>& view)
        : footprint_(g, mode, view),
          drawn_(mode == Culling::exact || g.opacity > T(0)),
          parked_(parked_tile(static_cast<std::uint32_t>(view.tiles_x) * view.tiles_y)) {}

    /// The tile the pair emitted at `tile` sorts under at the current pose.
    CATGS_HD std::uint32_t operator()(std::uint32_t tile) {
        return drawn_ && footprint_.touches(tile) ? tile : parked_;
    }

private:
    TouchedTiles<T> footprint_;
    bool drawn_;
    std::uint32_t parked_;
};

/// Does a single-frame footprint touch tile `tile`? (One question of TouchedTiles.)
template <typename T>
CATGS_HD bool touches_tile(const Projected<T>& g, Culling mode, const View<T>& view, std::uint32_t tile) {
    return TouchedTiles<T>(g, mode, view).touches(tile);
}

/// Windows of at most this many poses get their own kernel instances (preprocess.cu, keys.cu):
/// loops over the poses run to the constant MaxWindow, which the compiler unrolls, so the
/// per-pose arrays stay in registers and each pose's ellipse is set up once, not once a row.
/// Larger instances loop to the window's size and set the ellipses up a row at a time: an
/// array of 16 of them in local memory cost more than the set-up (W = 3 key frames on the kit's
/// city at 4K: 11.2 against 9.8 ms, H200, 2026-12-04).
inline constexpr int kUnrolledWindow = 2;

/// How far a loop over a window's poses runs: to the constant MaxWindow in the unrolled
/// instances (testing k < window inside), to the window's size otherwise.
template <int MaxWindow>
CATGS_HD int pose_loop_bound(int window) {
    return MaxWindow <= kUnrolledWindow ? MaxWindow : window;
}

/// The tiles of one row in the union of MaxWindow spans (the first `window` of them), as
/// maximal runs from `start` (the leftmost span's first tile) left to right; `none` is past
/// every span. Returns how many.
template <int MaxWindow, typename Emit>
CATGS_HD std::uint32_t union_runs(const TileSpan (&spans)[MaxWindow], int window, int start, int none, int ty,
                                  int tiles_x, Emit& emit) {
    std::uint32_t n = 0;
    while (start < none) {
        int end = start;  // grow the run while a span starts inside it and reaches past its end
        for (bool grew = true; grew;) {
            grew = false;
            for (int k = 0; k < MaxWindow; ++k)
                if (k < window && spans[k].x0 <= end && spans[k].x1 > end) {
                    end = spans[k].x1;
                    grew = true;
                }
        }
        for (int tx = start; tx < end; ++tx) emit(static_cast<std::uint32_t>(ty * tiles_x + tx));
        n += static_cast<std::uint32_t>(end - start);
        int next = none;  // the next run starts at the leftmost span beyond this one
        for (int k = 0; k < MaxWindow; ++k)
            if (k < window && spans[k].x0 < spans[k].x1 && spans[k].x0 > end && spans[k].x0 < next) next = spans[k].x0;
        start = next;
    }
    return n;
}

/// for_each_window_tile's union of several poses' footprints within `u`, a tile row at a time,
/// left to right. The unrolled instance emits maximal runs of tiles (O(W) work a run); the
/// others test each tile against the poses' spans, stopping at the first that holds it, which
/// measured faster there (W = 3 key frames on the kit's 4K paths: runs 4-5% slower, H200,
/// 2026-12-04). Both give the same tiles in the same order.
template <int MaxWindow, typename T, typename Emit>
CATGS_HD std::uint32_t window_union_tiles(const Projected<T>* poses, const TileRect* rects, const TileRect& u,
                                          int window, Culling mode, T guard, const View<T>& view, Emit& emit) {
    constexpr bool kUnrolled = MaxWindow <= kUnrolledWindow;
    const int poses_n = pose_loop_bound<MaxWindow>(window);
    EllipseRows<T> ellipses[kUnrolled ? MaxWindow : 1];
    if constexpr (kUnrolled)
        for (int k = 0; k < MaxWindow; ++k)
            if (mode == Culling::opacity_aware && k < window && !rects[k].empty())
                ellipses[k] = EllipseRows<T>(poses[k], opacity_level(poses[k].opacity));
    std::uint32_t n = 0;
    for (int ty = u.y0; ty < u.y1; ++ty) {
        TileSpan spans[MaxWindow];
        int start = u.x1, last = u.x0;  // the leftmost tile of any pose's span (u.x1: none), the rightmost end
        for (int k = 0; k < poses_n; ++k) {
            if (k >= window || rects[k].empty()) {
                spans[k] = TileSpan{0, 0};
                continue;
            }
            if constexpr (kUnrolled)
                spans[k] = footprint_row(poses[k], mode, rects[k], ty, view, guard, ellipses[k]);
            else
                spans[k] = footprint_row(poses[k], mode, rects[k], ty, view, guard,
                                         EllipseRows<T>(poses[k], opacity_level(poses[k].opacity)));
            if (spans[k].x0 >= spans[k].x1) continue;
            start = spans[k].x0 < start ? spans[k].x0 : start;
            last = spans[k].x1 > last ? spans[k].x1 : last;
        }
        if constexpr (!kUnrolled) {
            for (int tx = start; tx < last; ++tx) {
                bool hit = false;
                for (int k = 0; k < window && !hit; ++k) hit = tx >= spans[k].x0 && tx < spans[k].x1;
                if (!hit) continue;
                emit(static_cast<std::uint32_t>(ty * view.tiles_x + tx));
                ++n;
            }
        } else {
            n += union_runs(spans, window, start, u.x1, ty, view.tiles_x, emit);
        }
    }
    return n;
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
    const int poses_n = pose_loop_bound<MaxWindow>(window);
    for (int k = 0; k < poses_n; ++k) {
        rects[k] = k < window && (valid >> k & 1u) ? tile_rect(poses[k], mode, view.tiles_x, view.tiles_y, guard)
                                                   : TileRect{0, 0, 0, 0};
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
    if (MaxWindow == 1 || window == 1) {  // the plain pipeline: one span per row, no union
        const EllipseRows<T> ellipse(poses[0], opacity_level(poses[0].opacity));
        for (int ty = u.y0; ty < u.y1; ++ty) {
            const TileSpan s = footprint_row(poses[0], mode, rects[0], ty, view, guard, ellipse);
            for (int tx = s.x0; tx < s.x1; ++tx) emit(static_cast<std::uint32_t>(ty * view.tiles_x + tx));
            n += static_cast<std::uint32_t>(s.x1 - s.x0);
        }
        return n;
    }
    if constexpr (MaxWindow > 1) n = window_union_tiles<MaxWindow>(poses, rects, u, window, mode, guard, view, emit);
    return n;
}

/// The single-frame predicate: the tiles one projected Gaussian touches under `mode`.
template <typename T, typename Emit>
CATGS_HD std::uint32_t for_each_touched_tile(const Projected<T>& g, Culling mode, const View<T>& view, Emit&& emit,
                                             TileRows rows = {}) {
    return for_each_window_tile<1>(&g, 1u, 1, mode, T(0), view, emit, rows);
}

}  // namespace catgs
