// The tile stages that the backends share, against double references written apart from them:
// the tile rectangle of a footprint and the ellipse-tile test (stages/tiles.hpp), and the row
// spans of a window's tiles (for_each_window_tile). Double must match its reference to
// rounding; float must decide as double except where the double value lies within the quoted
// tolerance of the threshold. test_stage_math.cpp holds the other stages' functions;
// gpu/test_stage_math_device.cu runs the same functions on the device.

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <iostream>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "catgs/constants.hpp"
#include "catgs/stages/footprint.hpp"
#include "catgs/stages/tiles.hpp"
#include "catgs/stages/view.hpp"
#include "stage_inputs.hpp"
#include "test_util.hpp"

namespace catgs {
namespace {

namespace stage = test::stage;
// --- Tile rectangles ---------------------------------------------------------------------

/// The tiles [first, last + 1) of the grid that the closed pixel-index interval [lo, hi]
/// reaches (pixel i of tile t: 16 t <= i < 16 t + 16), clamped to [0, tiles].
std::array<int, 2> tile_span(double lo, double hi, int tiles) {
    auto clamp_tile = [&](double v) { return static_cast<int>(std::clamp(v, 0.0, static_cast<double>(tiles))); };
    return {clamp_tile(std::floor(lo / kTileSize)), clamp_tile(std::floor(hi / kTileSize) + 1)};
}

/// The reference rectangle: opacity-aware, the tiles of the box mean +- sqrt(level cov_ii)
/// (pixel i sampled at i + 0.5); bbox3sigma, graphdeco's square of radius ceil(3 sqrt of the
/// larger eigenvalue) around mean - 0.5, the eigenvalue floored as graphdeco floors it.
TileRect reference_rect(const Projected<double>& g, Culling mode, int tiles_x, int tiles_y, double guard) {
    if (mode == Culling::bbox3sigma) {
        const double mid = 0.5 * (g.cov.x + g.cov.z), det = g.cov.x * g.cov.z - g.cov.y * g.cov.y;
        const double lambda = mid + std::sqrt(std::max(mid * mid - det, kBBoxEigenFloor));
        const double r = std::ceil(3 * std::sqrt(lambda)) + guard;
        const double px = g.mean.x - 0.5, py = g.mean.y - 0.5;
        auto clamp_tile = [](double v, int tiles) {
            return static_cast<int>(std::clamp(std::floor(v), 0.0, static_cast<double>(tiles)));
        };
        return {clamp_tile((px - r) / kTileSize, tiles_x), clamp_tile((py - r) / kTileSize, tiles_y),
                clamp_tile((px + r + kTileSize - 1) / kTileSize, tiles_x),
                clamp_tile((py + r + kTileSize - 1) / kTileSize, tiles_y)};
    }
    const double level = 2 * std::log(255.0 * g.opacity) * 1.001 + 1e-3;
    if (!(level > 0)) return {0, 0, 0, 0};
    const double hx = std::sqrt(level * g.cov.x) + guard, hy = std::sqrt(level * g.cov.z) + guard;
    const auto x = tile_span(g.mean.x - hx - 0.5, g.mean.x + hx - 0.5, tiles_x);
    const auto y = tile_span(g.mean.y - hy - 0.5, g.mean.y + hy - 0.5, tiles_y);
    return {x[0], y[0], x[1], y[1]};
}

bool same_rect(const TileRect& a, const TileRect& b) {
    return (a.empty() && b.empty()) || (a.x0 == b.x0 && a.y0 == b.y0 && a.x1 == b.x1 && a.y1 == b.y1);
}

/// How far (pixels) an edge of the double footprint lies from the nearest tile boundary at
/// which its rectangle would change; float may round across a boundary that close.
double distance_to_tile_boundary(const Projected<double>& g, Culling mode, double guard) {
    double edges[4];
    if (mode == Culling::bbox3sigma) {
        const Vec2<double> e = footprint_extent(g, mode);
        const double r = e.x + guard;
        edges[0] = g.mean.x - 0.5 - r, edges[1] = g.mean.x - 0.5 + r + kTileSize - 1;
        edges[2] = g.mean.y - 0.5 - r, edges[3] = g.mean.y - 0.5 + r + kTileSize - 1;
    } else {
        const Vec2<double> e = footprint_extent(g, mode);
        edges[0] = g.mean.x - e.x - guard - 0.5, edges[1] = g.mean.x + e.x + guard - 0.5;
        edges[2] = g.mean.y - e.y - guard - 0.5, edges[3] = g.mean.y + e.y + guard - 0.5;
    }
    double d = std::numeric_limits<double>::infinity();
    for (double v : edges) d = std::min(d, std::fabs(v - kTileSize * std::round(v / kTileSize)));
    if (mode == Culling::bbox3sigma) {
        // The radius is 3 sigma rounded up to a whole pixel: where 3 sigma is within rounding
        // of an integer, float's radius can be a pixel larger or smaller.
        const double mid = 0.5 * (g.cov.x + g.cov.z), det = g.cov.x * g.cov.z - g.cov.y * g.cov.y;
        const double three_sigma = 3 * std::sqrt(mid + std::sqrt(std::max(mid * mid - det, kBBoxEigenFloor)));
        if (std::fabs(three_sigma - std::round(three_sigma)) < 1e-3) d = 0;
    }
    return d;
}

// Float's rectangle is double's unless an edge lies within 1e-3 px of a tile boundary, or
// bbox3sigma's 3 sigma within 1e-3 px of a whole pixel (where its ceil jumps): about 1 case in
// 800 is that close, and in 400000 none has differed (the inputs are the same floats, so
// only float's sqrt and log differ from double's).
TEST(StageTiles, TileRectIsTheTilesOfTheFootprint) {
    const std::uint64_t seed = test::fresh_seed("stage tile rect");
    std::mt19937_64 rng(seed);
    int compared = 0, in_band = 0;
    double closest_flip = std::numeric_limits<double>::infinity();
    for (int i = 0; i < 20000; ++i) {
        const int width = static_cast<int>(stage::uniform(rng, 1, 2000)),
                  height = static_cast<int>(stage::uniform(rng, 1, 1200));
        const int tiles_x = tiles_for(width), tiles_y = tiles_for(height);
        const Projected<float> pf = stage::random_projected<float>(rng, width, height);
        const Projected<double> pd = stage::widened(pf);
        const double guard = i % 3 == 0 ? stage::uniform(rng, 0, 8) : 0.0;
        for (Culling mode : {Culling::bbox3sigma, Culling::opacity_aware}) {
            const TileRect d = tile_rect(pd, mode, tiles_x, tiles_y, guard);
            ASSERT_TRUE(same_rect(d, reference_rect(pd, mode, tiles_x, tiles_y, guard)))
                << culling_name(mode) << " case " << i << " (CATGS_TEST_SEED=" << seed << ")";
            const TileRect f = tile_rect(pf, mode, tiles_x, tiles_y, static_cast<float>(guard));
            ++compared;
            const double distance = distance_to_tile_boundary(pd, mode, guard);
            if (!same_rect(f, d)) closest_flip = std::min(closest_flip, distance);
            if (distance < 1e-3) {
                ++in_band;
                continue;
            }
            EXPECT_TRUE(same_rect(f, d)) << culling_name(mode) << " case " << i << " (CATGS_TEST_SEED=" << seed << ")";
        }
        const TileRect exact = tile_rect(pf, Culling::exact, tiles_x, tiles_y);
        EXPECT_TRUE(exact.x0 == 0 && exact.y0 == 0 && exact.x1 == tiles_x && exact.y1 == tiles_y);
    }
    std::cout << "[stage] tile_rect: " << compared << " compared, " << in_band << " within 1e-3 px of a tile boundary, "
              << "float differs at most " << (std::isinf(closest_flip) ? 0 : closest_flip) << " px from one"
              << std::endl;
    EXPECT_LT(in_band, compared / 100);
}

// --- The ellipse-tile test ---------------------------------------------------------------

/// Where q is least over a tile's region, and its value there.
struct TileMinimum {
    double q, dx, dy;  // q and the offsets from the mean where it is reached
};

/// The least q over the rectangle of a tile's pixel centres grown by `guard` (clipped to the
/// image as ellipse_touches_tile clips it), found by ternary search along each edge (q is
/// convex along a line): a different algorithm from the closed-form edge minimum.
TileMinimum reference_tile_minimum(const Projected<double>& g, int tx, int ty, int width, int height, double guard) {
    const double x0 = tx * kTileSize + 0.5 - guard, x1 = std::min(tx * kTileSize + kTileSize, width) - 0.5 + guard;
    const double y0 = ty * kTileSize + 0.5 - guard, y1 = std::min(ty * kTileSize + kTileSize, height) - 0.5 + guard;
    if (g.mean.x >= x0 && g.mean.x <= x1 && g.mean.y >= y0 && g.mean.y <= y1) return {0, 0, 0};
    auto at = [&](double x, double y) {
        return TileMinimum{conic_form(g.conic, x - g.mean.x, y - g.mean.y), x - g.mean.x, y - g.mean.y};
    };
    auto less = [](const TileMinimum& a, const TileMinimum& b) { return a.q < b.q; };
    auto edge_min = [&](double ax, double ay, double bx, double by) {
        double lo = 0, hi = 1;
        for (int it = 0; it < 100; ++it) {  // (2/3)^100 of the edge: below double rounding
            const double m1 = lo + (hi - lo) / 3, m2 = hi - (hi - lo) / 3;
            if (at(ax + m1 * (bx - ax), ay + m1 * (by - ay)).q < at(ax + m2 * (bx - ax), ay + m2 * (by - ay)).q)
                hi = m2;
            else
                lo = m1;
        }
        const double s = 0.5 * (lo + hi);
        return std::min({at(ax + s * (bx - ax), ay + s * (by - ay)), at(ax, ay), at(bx, by)}, less);
    };
    return std::min(
        {edge_min(x0, y0, x1, y0), edge_min(x0, y1, x1, y1), edge_min(x0, y0, x0, y1), edge_min(x1, y0, x1, y1)}, less);
}

double reference_min_q(const Projected<double>& g, int tx, int ty, int width, int height, double guard) {
    return reference_tile_minimum(g, tx, ty, width, height, guard).q;
}

/// How far float's q at a tile's nearest point can stray from the exact q there (a bound with
/// a factor 2 to spare): each offset (pixel + 0.5 - guard - mean) is rounded twice, which moves
/// q by its gradient times that error, and the conic form's three rounded terms cancel for a
/// needle seen along its length (terms of 1e4 summing to a level of 10), so the error scales
/// with their magnitudes, not with q.
double float_q_error(const Projected<double>& g, const TileMinimum& m, double far_px, double guard) {
    constexpr double u = std::numeric_limits<float>::epsilon() / 2;
    const double a = std::fabs(g.conic.x), b = std::fabs(g.conic.y), c = std::fabs(g.conic.z);
    const double dx = std::fabs(m.dx), dy = std::fabs(m.dy);
    const double offset_error = 2 * u * (far_px + 1 + guard + std::max(std::fabs(g.mean.x), std::fabs(g.mean.y)));
    const double gradient = 2 * (a * dx + b * dy) + 2 * (b * dx + c * dy);
    const double terms = a * dx * dx + 2 * b * dx * dy + c * dy * dy;
    return 2 * (6 * u * terms + gradient * offset_error);
}

// Double decides as its reference except within 1e-9 (relative) of the level; float as double
// except within float's rounding error of q at the tile's nearest point (float_q_error). A
// fixed band of 1e-4 of the level was not enough: a needle 200 px long seen along its length
// flipped at 2e-4 (seed 4026791311231595935, case 1199), its q the sum of terms near 1e4.
TEST(StageTiles, EllipseTouchesTileWhereTheEllipseReachesTheTilesPixelCentres) {
    const std::uint64_t seed = test::fresh_seed("stage ellipse tile");
    std::mt19937_64 rng(seed);
    int touched = 0, missed = 0, double_band = 0, float_band = 0;
    double widest_flip = 0, flip_in_bounds = 0;
    for (int i = 0; i < 1500; ++i) {
        const int width = static_cast<int>(stage::uniform(rng, 17, 400)),
                  height = static_cast<int>(stage::uniform(rng, 17, 300));
        const Projected<float> pf = stage::random_projected<float>(rng, width, height);
        const Projected<double> pd = stage::widened(pf);
        const float level_f = opacity_level(pf.opacity);
        if (!(level_f > 0)) continue;
        const double level = level_f;
        const double guard = i % 4 == 0 ? stage::uniform(rng, 0, 6) : 0.0;
        for (int ty = 0; ty < tiles_for(height); ++ty)
            for (int tx = 0; tx < tiles_for(width); ++tx) {
                const TileMinimum m = reference_tile_minimum(pd, tx, ty, width, height, guard);
                const double min_q = m.q;
                const bool d = ellipse_touches_tile(pd, level, tx, ty, width, height, guard);
                const bool f = ellipse_touches_tile(pf, level_f, tx, ty, width, height, static_cast<float>(guard));
                (d ? touched : missed) += 1;
                const double margin = std::fabs(min_q - level) / std::max(1.0, level);
                const double far_px = (std::max(tx, ty) + 1) * kTileSize;
                const double float_error = float_q_error(pd, m, far_px, guard);
                if (f != d) {
                    widest_flip = std::max(widest_flip, margin);
                    flip_in_bounds = std::max(flip_in_bounds, std::fabs(min_q - level) / float_error);
                }
                if (margin < 1e-9) {
                    ++double_band;
                    continue;
                }
                EXPECT_EQ(d, min_q <= level) << "case " << i << " tile " << tx << "," << ty << ": min q " << min_q
                                             << ", level " << level << " (CATGS_TEST_SEED=" << seed << ")";
                if (std::fabs(min_q - level) <= float_error) {
                    ++float_band;
                    continue;
                }
                EXPECT_EQ(f, d) << "case " << i << " tile " << tx << "," << ty << " (CATGS_TEST_SEED=" << seed << ")";
                // Soundness, the reason for the test: a tile it rejects has no pixel centre with
                // q <= level (pixels there would draw with alpha >= 1/255).
                if (!d && guard == 0) {
                    for (int y = ty * kTileSize; y < std::min(ty * kTileSize + kTileSize, height); ++y)
                        for (int x = tx * kTileSize; x < std::min(tx * kTileSize + kTileSize, width); ++x)
                            ASSERT_GT(conic_form(pd.conic, x + 0.5 - pd.mean.x, y + 0.5 - pd.mean.y), level)
                                << "case " << i << " pixel " << x << "," << y << " (CATGS_TEST_SEED=" << seed << ")";
                }
            }
    }
    std::cout << "[stage] ellipse_touches_tile: " << touched << " touched, " << missed << " missed, " << double_band
              << " within 1e-9 of the level, " << float_band << " within float's rounding of it; float differs at most "
              << widest_flip << " from the level, at most " << flip_in_bounds << " of the rounding bound" << std::endl;
    EXPECT_GT(touched, 1000);
    EXPECT_GT(missed, 1000);
    // The band must stay a band: a bound so loose that it excused most tiles would test nothing.
    EXPECT_LT(float_band, (touched + missed) / 1000);
}

/// Asks one TouchedTiles about every tile of the grid in `order` and checks each answer
/// against `emitted` (for_each_touched_tile's tiles). Returns how many it said it touches.
template <typename T>
int check_touched_tiles(const Projected<T>& g, Culling mode, const View<T>& view, const std::vector<int>& emitted,
                        const std::vector<std::uint32_t>& order, const std::string& where) {
    TouchedTiles<T> touched(g, mode, view);
    int yes = 0;
    for (std::uint32_t tile : order) {
        const bool got = touched.touches(tile);
        yes += got;
        EXPECT_EQ(got, emitted[tile] > 0) << where << " tile " << tile;
        if (got != (emitted[tile] > 0)) return yes;  // one message a case
    }
    return yes;
}

// TouchedTiles (the re-key's question, tile by tile) says yes exactly for the tiles
// for_each_touched_tile emits, whatever order it is asked in: row by row as a key frame
// emits, shuffled, and each tile asked twice in a row; for both precisions and every culling
// mode, on conics that are not positive definite (the per-tile fallback) and NaN means too.
TEST(StageTiles, TouchedTilesAreTheTilesTheFootprintEmits) {
    const std::uint64_t seed = test::fresh_seed("stage touched tiles");
    std::mt19937_64 rng(seed);
    int touched = 0, asked = 0;
    for (int i = 0; i < 600; ++i) {
        const int width = static_cast<int>(stage::uniform(rng, 1, 700)),
                  height = static_cast<int>(stage::uniform(rng, 1, 500));
        Projected<float> pf = stage::random_projected<float>(rng, width, height);
        if (i % 10 == 3) pf.conic.y = 1.01f * std::sqrt(pf.conic.x * pf.conic.z);  // indefinite
        if (i % 25 == 7) pf.mean.x = std::numeric_limits<float>::quiet_NaN();
        const Projected<double> pd = stage::widened(pf);
        const std::string where = "case " + std::to_string(i) + " (CATGS_TEST_SEED=" + std::to_string(seed) + ")";
        const auto check = [&](const auto& g, const auto& view, Culling mode, const std::string& what) {
            std::vector<int> emitted(static_cast<std::size_t>(view.tiles_x * view.tiles_y), 0);
            std::vector<std::uint32_t> in_emission_order;
            for_each_touched_tile(g, mode, view, [&](std::uint32_t t) {
                ++emitted[t];
                in_emission_order.push_back(t);
            });
            std::vector<std::uint32_t> all(emitted.size());
            for (std::size_t t = 0; t < all.size(); ++t) all[t] = static_cast<std::uint32_t>(t);
            std::vector<std::uint32_t> twice;
            for (std::uint32_t t : all) twice.insert(twice.end(), {t, t});
            std::vector<std::uint32_t> shuffled = all;
            std::shuffle(shuffled.begin(), shuffled.end(), rng);
            const std::string here = what + " " + culling_name(mode) + " " + where;
            if (mode == Culling::exact) {  // one entry for tile 0: the list every tile shares
                EXPECT_EQ(in_emission_order, std::vector<std::uint32_t>{0}) << here;
                std::fill(emitted.begin(), emitted.end(), 1);
            }
            const int n = check_touched_tiles(g, mode, view, emitted, all, here + " row by row");
            EXPECT_EQ(check_touched_tiles(g, mode, view, emitted, shuffled, here + " shuffled"), n) << here;
            EXPECT_EQ(check_touched_tiles(g, mode, view, emitted, twice, here + " twice"), 2 * n) << here;
            if (mode != Culling::exact) {
                EXPECT_EQ(static_cast<std::size_t>(n), in_emission_order.size()) << here;
                EXPECT_EQ(check_touched_tiles(g, mode, view, emitted, in_emission_order, here + " as emitted"), n)
                    << here;
            }
            if (mode == Culling::exact) return;
            touched += n;
            asked += static_cast<int>(all.size());
        };
        for (Culling mode : {Culling::bbox3sigma, Culling::opacity_aware, Culling::exact}) {
            check(pf, stage::image_view<float>(width, height), mode, "float");
            check(pd, stage::image_view<double>(width, height), mode, "double");
        }
    }
    std::cout << "[stage] TouchedTiles: " << touched << " of " << asked << " tiles touched (culled modes)" << std::endl;
    EXPECT_GT(touched, asked / 50);
    EXPECT_LT(touched, asked / 2);
}

/// The tile sets of for_each_window_tile (row spans) against the per-tile reference: a tile is
/// in the union when some pose's rectangle holds it and that pose's ellipse reaches it
/// (reference_min_q <= level). Returns the tiles decided within `band` (relative) of a level,
/// where either answer is sound.
template <typename T>
int check_row_spans(const std::vector<Projected<T>>& poses, int width, int height, double guard, double band,
                    int& touched, const std::string& where) {
    const View<T> view = stage::image_view<T>(width, height);
    std::vector<int> emitted(static_cast<std::size_t>(view.tiles_x * view.tiles_y), 0);
    std::vector<std::uint32_t> sequence;
    Projected<T> window[kMaxWindow];
    std::copy(poses.begin(), poses.end(), window);
    const std::uint32_t valid = (1u << poses.size()) - 1u;
    const int size = static_cast<int>(poses.size());
    const std::uint32_t n = for_each_window_tile<kMaxWindow>(window, valid, size, Culling::opacity_aware,
                                                             static_cast<T>(guard), view, [&](std::uint32_t t) {
                                                                 ++emitted[t];
                                                                 sequence.push_back(t);
                                                             });
    if (size <= kUnrolledWindow) {
        // The small windows' unrolled instance (the GPU's kernels for W <= kUnrolledWindow)
        // emits the same tiles in the same order.
        std::vector<std::uint32_t> unrolled;
        const std::uint32_t m =
            for_each_window_tile<kUnrolledWindow>(window, valid, size, Culling::opacity_aware, static_cast<T>(guard),
                                                  view, [&](std::uint32_t t) { unrolled.push_back(t); });
        EXPECT_EQ(m, n) << where << " (unrolled instance)";
        EXPECT_EQ(unrolled, sequence) << where << " (unrolled instance)";
    }
    int near_level = 0, counted = 0;
    for (int ty = 0; ty < view.tiles_y; ++ty)
        for (int tx = 0; tx < view.tiles_x; ++tx) {
            const int got = emitted[static_cast<std::size_t>(ty * view.tiles_x + tx)];
            counted += got;
            EXPECT_LE(got, 1) << where << " tile " << tx << "," << ty << " emitted twice";
            bool expected = false, close = false;
            for (const Projected<T>& g : poses) {
                const TileRect r =
                    tile_rect(g, Culling::opacity_aware, view.tiles_x, view.tiles_y, static_cast<T>(guard));
                if (tx < r.x0 || tx >= r.x1 || ty < r.y0 || ty >= r.y1) continue;
                const double level = static_cast<double>(opacity_level(g.opacity));
                Projected<double> d{};
                d.mean = {static_cast<double>(g.mean.x), static_cast<double>(g.mean.y)};
                d.conic = {static_cast<double>(g.conic.x), static_cast<double>(g.conic.y),
                           static_cast<double>(g.conic.z)};
                const double min_q = reference_min_q(d, tx, ty, width, height, guard);
                expected = expected || min_q <= level;
                close = close || std::fabs(min_q - level) <= band * std::max(1.0, level);
            }
            touched += got;
            if (close) {
                ++near_level;
                continue;
            }
            EXPECT_EQ(got == 1, expected) << where << " tile " << tx << "," << ty;
        }
    EXPECT_EQ(static_cast<int>(n), counted) << where;
    return near_level;
}

// The row spans give the tiles the per-tile test gives (ellipse_touches_tile, here through its
// ternary-search reference), one pose or the union of a window's, with and without a guard:
// exactly in double except within 1e-9 of a level, and in float except within 1e-6 (the
// inputs are the same floats; the spans are computed in double either way).
TEST(StageTiles, RowSpansAreTheTilesThePerTileTestTouches) {
    const std::uint64_t seed = test::fresh_seed("stage row spans");
    std::mt19937_64 rng(seed);
    int touched = 0, near_level = 0;
    for (int i = 0; i < 1200; ++i) {
        const int width = static_cast<int>(stage::uniform(rng, 17, 400)),
                  height = static_cast<int>(stage::uniform(rng, 17, 300));
        const int window = i % 3 == 0 ? static_cast<int>(stage::uniform(rng, 2, 6)) : i % 3 == 1 ? 1 : 2;
        std::vector<Projected<float>> pf;
        const Projected<float> first = stage::random_projected<float>(rng, width, height);
        for (int k = 0; k < window; ++k) {
            // A window's poses see the same Gaussian a little moved and reshaped.
            Projected<float> g = k == 0 ? first : stage::random_projected<float>(rng, width, height);
            if (k > 0) {
                // Every sixth window moves far enough that a small footprint's spans of one
                // row fall apart (the union is then several runs of tiles).
                const double move = i % 6 == 3 ? 80 : 20;
                g.mean = {first.mean.x + static_cast<float>(stage::uniform(rng, -move, move)),
                          first.mean.y + static_cast<float>(stage::uniform(rng, -move, move))};
                g.opacity = first.opacity;
            }
            pf.push_back(g);
        }
        std::vector<Projected<double>> pd;
        for (const Projected<float>& g : pf) pd.push_back(stage::widened(g));
        const double guard = i % 4 == 0 ? stage::uniform(rng, 0, 6) : 0.0;
        const std::string where = "case " + std::to_string(i) + " (CATGS_TEST_SEED=" + std::to_string(seed) + ")";
        near_level += check_row_spans(pd, width, height, guard, 1e-9, touched, "double " + where);
        check_row_spans(pf, width, height, guard, 1e-6, touched, "float " + where);
    }
    std::cout << "[stage] row spans: " << touched << " tiles touched, " << near_level << " within 1e-9 of a level"
              << std::endl;
    EXPECT_GT(touched, 5000);
}

}  // namespace
}  // namespace catgs
