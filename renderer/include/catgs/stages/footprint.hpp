// A projected Gaussian's footprint on the image: the level set that culling keeps, its pixel
// extent and box, and a bound on its extent at nearby poses. Tile lists (stages/tiles.hpp),
// the rasterizer's pixel skip and the cache envelope (stages/envelope.hpp) all measure it here.
#pragma once

#include "catgs/constants.hpp"
#include "catgs/hd.hpp"
#include "catgs/math.hpp"
#include "catgs/stages/culling.hpp"
#include "catgs/stages/project.hpp"

namespace catgs {

/// Relative and absolute slack on the opacity-aware level set, so that rounding in the
/// rasterizer's alpha can never make a pixel visible that the tile test rejected.
inline constexpr double kOpacityLevelRelativeSlack = 1e-3;
inline constexpr double kOpacityLevelAbsoluteSlack = 1e-3;

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

}  // namespace catgs
