// Occlusion cut: a plain frame leaves out of its lists the Gaussians that lie behind where the
// last frame's tiles turned opaque, and every tile checks that it turned opaque in front of
// what was left out; a frame where one did not is drawn again without the cut.
//
// Why. Each pixel stops blending once its transmittance would fall below 1e-4 (blend.hpp), and
// on dense captures most pairs lie behind that point: on the bench kit's city_ring at 4K the
// rasterizer reaches about a quarter of the 27.5M pairs it is handed (ncu, session 12). The
// other three quarters still cost their share of preprocess (SH colour), keys and both sorts.
//
// The rule, per Gaussian (preprocess): left out when its sort depth (Projected::key_depth) is
// greater than the predicted cut of every tile of its tile rectangle (cut_over_rect, through a
// max pyramid, so a few reads a Gaussian). Per tile (rasterize): the tile's pixels must all
// have stopped at a Gaussian no deeper than the tile's predicted cut. Then everything left out
// of that tile lies behind every pixel's stop, and the tile's pixels are the ones the full list
// draws, bit for bit: the kept list holds every Gaussian up to the cut in the same order. A
// tile that stopped deeper, or not at all, is a miss; the frame is then drawn again, whole.
//
// The prediction: the depths at which the last frame's tiles stopped (the cut it recorded),
// each tile taking the deepest of its neighbourhood (the camera's turn moves the content by
// up to a radius of tiles), grown by the turn and the step in depth (predicted_cut). Tiles that
// did not stop, and neighbourhoods that reach one, predict +infinity: nothing is left out there.
#pragma once

#include <cmath>

#include "catgs/constants.hpp"
#include "catgs/hd.hpp"
#include "catgs/stages/tiles.hpp"

namespace catgs {

/// Levels of the cut pyramid: 1 + log2 of the longest tile side (16384 px / 16 = 1024 tiles).
inline constexpr int kOcclusionMaxLevels = 12;
/// Neighbourhood radius (tiles) past which a turn between frames disables the cut for the frame:
/// a wider max predicts little that is left out, and the frame would likely miss anyway.
inline constexpr int kOcclusionMaxRadius = 4;
/// Relative depth margin on each predicted cut: a tile's stop moves by a few Gaussians from one
/// frame to the next, and a miss costs a whole frame.
inline constexpr double kOcclusionDepthMargin = 0.02;

/// The cut pyramid: level 0 is one predicted depth a tile, each level above the max of 2x2 cells
/// below (the last row or column alone where the side is odd), up to one cell.
struct OcclusionPyramid {
    int levels = 0;
    int width[kOcclusionMaxLevels] = {};
    int height[kOcclusionMaxLevels] = {};
    int offset[kOcclusionMaxLevels] = {};
    int cells = 0;  // all levels

    CATGS_HD int at(int level, int x, int y) const { return offset[level] + y * width[level] + x; }
};

/// The pyramid of a grid of tiles_x x tiles_y tiles (both >= 1).
CATGS_HD inline OcclusionPyramid occlusion_pyramid(int tiles_x, int tiles_y) {
    OcclusionPyramid p;
    int w = tiles_x, h = tiles_y;
    for (;;) {
        p.width[p.levels] = w;
        p.height[p.levels] = h;
        p.offset[p.levels] = p.cells;
        p.cells += w * h;
        ++p.levels;
        if ((w == 1 && h == 1) || p.levels == kOcclusionMaxLevels) break;
        w = (w + 1) / 2;
        h = (h + 1) / 2;
    }
    return p;
}

/// Cell (x, y) of `level` (>= 1): the max of the 2x2 cells below it that exist.
CATGS_HD inline float pyramid_cell(const OcclusionPyramid& p, const float* cells, int level, int x, int y) {
    const int below = level - 1;
    float deepest = -INFINITY;
    for (int by = 2 * y; by < 2 * y + 2 && by < p.height[below]; ++by)
        for (int bx = 2 * x; bx < 2 * x + 2 && bx < p.width[below]; ++bx) {
            const float c = cells[p.at(below, bx, by)];
            deepest = c > deepest ? c : deepest;
        }
    return deepest;
}

/// The deepest predicted cut over the tiles of `rect` (not empty, inside the grid), or more:
/// read at the lowest level where the rectangle spans at most 2x2 cells.
CATGS_HD inline float cut_over_rect(const OcclusionPyramid& p, const float* cuts, TileRect rect) {
    int x0 = rect.x0, x1 = rect.x1 - 1, y0 = rect.y0, y1 = rect.y1 - 1, level = 0;
    while (level + 1 < p.levels && (x1 - x0 > 1 || y1 - y0 > 1)) {
        x0 >>= 1;
        x1 >>= 1;
        y0 >>= 1;
        y1 >>= 1;
        ++level;
    }
    float deepest = -INFINITY;
    for (int y = y0; y <= y1; ++y)
        for (int x = x0; x <= x1; ++x) {
            const float c = cuts[p.at(level, x, y)];
            deepest = c > deepest ? c : deepest;
        }
    return deepest;
}

/// Whether a Gaussian of sort depth `key_depth` and tile rectangle `rect` is left out of the
/// lists. Never for an empty rectangle (no pairs anyway) or a NaN depth.
CATGS_HD inline bool occluded(const OcclusionPyramid& p, const float* cuts, TileRect rect, float key_depth) {
    return !rect.empty() && key_depth > cut_over_rect(p, cuts, rect);
}

/// How the last frame's cut is carried to this frame's prediction.
struct OcclusionMotion {
    bool usable = false;  // same grid, turned little enough
    int radius = 0;       // neighbourhood radius in tiles
    float grow = 1;       // relative depth margin
    float add = 0;        // absolute depth margin (the camera's step)
};

/// From the last frame's view to this one's: the turn angle (radians) moves content by up to
/// f * angle pixels and changes a depth z by up to about 1.5 z * angle (points off the axis lie
/// farther than their depth); the step changes any depth by at most its length.
inline OcclusionMotion occlusion_motion(double turn_angle, double step, double focal_px) {
    OcclusionMotion m;
    if (!(turn_angle >= 0) || !(step >= 0) || !(focal_px > 0)) return m;
    const double shift_tiles = std::ceil(focal_px * turn_angle / kTileSize);
    if (!(shift_tiles + 1 <= kOcclusionMaxRadius)) return m;
    m.usable = true;
    m.radius = 1 + static_cast<int>(shift_tiles);
    m.grow = static_cast<float>(1.0 + kOcclusionDepthMargin + 1.5 * turn_angle);
    m.add = static_cast<float>(step);
    return m;
}

/// Tile (tx, ty)'s predicted cut from the last frame's recorded cuts (`recorded`, one a tile of
/// the same grid): the deepest within `m.radius`, grown; +infinity where any is.
CATGS_HD inline float predicted_cut(const float* recorded, int tiles_x, int tiles_y, int tx, int ty,
                                    const OcclusionMotion& m) {
    float deepest = -INFINITY;
    for (int y = ty - m.radius; y <= ty + m.radius; ++y) {
        if (y < 0 || y >= tiles_y) continue;
        for (int x = tx - m.radius; x <= tx + m.radius; ++x) {
            if (x < 0 || x >= tiles_x) continue;
            const float c = recorded[y * tiles_x + x];
            if (!(c < INFINITY)) return INFINITY;  // also NaN: a max would skip it
            deepest = c > deepest ? c : deepest;
        }
    }
    return deepest * m.grow + m.add;
}

/// Whether a tile that stopped at a Gaussian of sort depth `stop_depth` (all its pixels done by
/// then; +infinity: not all stopped) drew what the full list draws, with predicted cut `cut`.
CATGS_HD inline bool occlusion_holds(float cut, float stop_depth) {
    return !(cut < INFINITY) || stop_depth <= cut;
}

}  // namespace catgs
