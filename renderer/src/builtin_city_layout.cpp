// The built-in city's layout: a seeded plan of roads, lots, parks, buildings with roof units,
// and park and street trees, as the surfaces that builtin_city.cpp fills with Gaussians.
// Built with -ffp-contract=off like builtin_city.cpp, whose bit-identity rules it follows.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

#include "builtin_city_detail.hpp"
#include "catgs/constants.hpp"

namespace catgs::city {
namespace {

constexpr double kParkChance = 0.2;
constexpr double kSplitChance = 0.6;  // per axis: a lot holds 1, 2 or 4 buildings
constexpr double kMinSetback = 2.0, kMaxSetback = 4.0;
constexpr double kMinFootprint = 8.0;
constexpr double kMinBuildingHeight = 8.0, kMaxBuildingHeight = 60.0;
constexpr int kMaxRoofUnits = 3;  // air-conditioning boxes on a roof

constexpr double kParkAreaPerTree = 90.0;
constexpr double kParkTreeMargin = 4.0;
constexpr double kStreetTreeSpacing = 12.0;
constexpr double kStreetTreeOffset = kRoadHalfWidth + 0.5 * kSidewalkWidth;  // mid-sidewalk
constexpr double kStreetTreeGapChance = 0.25;
constexpr double kStreetCanopyMax = 3.2;
static_assert(kStreetTreeOffset + kStreetCanopyMax < kRoadsideOffset + kMinSetback,
              "street canopies must end before the nearest facade");

const std::array<Rgb, 6> kWallColours{{{0.62, 0.61, 0.58},
                                       {0.76, 0.70, 0.58},
                                       {0.58, 0.32, 0.24},
                                       {0.85, 0.85, 0.82},
                                       {0.50, 0.55, 0.60},
                                       {0.80, 0.72, 0.55}}};
const std::array<Rgb, 4> kGlassColours{
    {{0.12, 0.18, 0.24}, {0.10, 0.22, 0.25}, {0.20, 0.22, 0.25}, {0.15, 0.15, 0.20}}};
const std::array<Rgb, 4> kRoofColours{{{0.35, 0.35, 0.35}, {0.25, 0.25, 0.27}, {0.55, 0.55, 0.52}, {0.30, 0.40, 0.25}}};
const std::array<Rgb, 4> kLeafColours{{{0.20, 0.38, 0.14}, {0.26, 0.42, 0.16}, {0.18, 0.32, 0.15}, {0.30, 0.40, 0.18}}};
constexpr Rgb kBark{0.33, 0.24, 0.16};
constexpr Rgb kMetal{0.70, 0.71, 0.72};

struct Footprint {
    double x0, y0, x1, y1;
    double height;
};

LotSpans lot_spans() {
    LotSpans spans;
    double begin = -kGroundHalfExtent;
    for (std::size_t i = 0; i < kRoadCentres.size(); ++i) {
        spans[i] = {begin, kRoadCentres[i] - kRoadsideOffset};
        begin = kRoadCentres[i] + kRoadsideOffset;
    }
    spans.back() = {begin, kGroundHalfExtent};
    return spans;
}

Rgb jittered(Rng& rng, Rgb c, double amount) {
    return (1.0 + amount * rng.symmetric()) * c;
}

Surface rect(Material material, V3 origin, V3 u, V3 v, double extent_u, double extent_v) {
    Surface s;
    s.shape = Shape::Rect;
    s.material = material;
    s.origin = origin;
    s.u = u;
    s.v = v;
    s.n = cross(u, v);
    s.extent_u = extent_u;
    s.extent_v = extent_v;
    s.area = extent_u * extent_v;
    return s;
}

// Four walls and a top. Walls run counter-clockwise seen from above, so u x v (v = up) is
// the outward normal of each.
void add_box(Layout& layout, Rng& rng, const Footprint& f, double z0, double z1, Material wall_material,
             const Look& wall_look, Material top_material, const Look& top_look) {
    const V3 up{0, 0, 1};
    const std::array<std::pair<V3, V3>, 4> walls{{{{f.x0, f.y0, z0}, {1, 0, 0}},
                                                  {{f.x1, f.y0, z0}, {0, 1, 0}},
                                                  {{f.x1, f.y1, z0}, {-1, 0, 0}},
                                                  {{f.x0, f.y1, z0}, {0, -1, 0}}}};
    for (const auto& [corner, along] : walls) {
        Surface s = rect(wall_material, corner, along, up, along.x != 0 ? f.x1 - f.x0 : f.y1 - f.y0, z1 - z0);
        s.look = wall_look;
        s.noise_key = rng.next();
        layout.surfaces.push_back(s);
    }
    Surface top = rect(top_material, {f.x0, f.y0, z1}, {1, 0, 0}, {0, 1, 0}, f.x1 - f.x0, f.y1 - f.y0);
    top.look = top_look;
    top.noise_key = rng.next();
    layout.surfaces.push_back(top);
}

void add_building(Layout& layout, Rng& rng, const Footprint& f) {
    Look wall;
    wall.base = jittered(rng, kWallColours[rng.index(kWallColours.size())], 0.06);
    wall.accent = jittered(rng, kGlassColours[rng.index(kGlassColours.size())], 0.1);
    wall.floor_height = rng.uniform(3.2, 4.2);
    wall.window_spacing = rng.uniform(2.6, 3.6);
    wall.window_width = wall.window_spacing * rng.uniform(0.45, 0.7);
    Look roof;
    roof.base = jittered(rng, kRoofColours[rng.index(kRoofColours.size())], 0.08);
    roof.accent = wall.base;  // the parapet continues the walls
    roof.solar = rng.chance(0.3);
    add_box(layout, rng, f, 0.0, f.height, Material::Facade, wall, Material::Roof, roof);

    const auto units = rng.index(kMaxRoofUnits + 1);
    for (std::size_t i = 0; i < units; ++i) {
        const double w = rng.uniform(2.0, 4.0), d = rng.uniform(1.5, 3.0), h = rng.uniform(1.0, 2.5);
        const double inset = kParapetWidth + 1.0;
        if (f.x1 - f.x0 < w + 2 * inset || f.y1 - f.y0 < d + 2 * inset) continue;
        Footprint unit{};
        unit.x0 = rng.uniform(f.x0 + inset, f.x1 - inset - w);
        unit.y0 = rng.uniform(f.y0 + inset, f.y1 - inset - d);
        unit.x1 = unit.x0 + w;
        unit.y1 = unit.y0 + d;
        Look metal;
        metal.base = jittered(rng, kMetal, 0.05);
        add_box(layout, rng, unit, f.height, f.height + h, Material::Metal, metal, Material::Metal, metal);
    }
}

void add_tree(Layout& layout, Rng& rng, double x, double y, double canopy_radius) {
    const double trunk_height = rng.uniform(2.5, 5.0);
    const double vertical_radius = canopy_radius * rng.uniform(0.7, 1.0);
    Surface trunk;
    trunk.shape = Shape::Cylinder;
    trunk.material = Material::Bark;
    trunk.origin = {x, y, 0};
    trunk.extent_u = rng.uniform(0.15, 0.35);
    trunk.extent_v = trunk_height + 0.5 * vertical_radius;  // into the canopy
    trunk.look.base = jittered(rng, kBark, 0.1);
    trunk.noise_key = rng.next();
    trunk.area = 2 * kPi * trunk.extent_u * trunk.extent_v;
    layout.surfaces.push_back(trunk);

    Surface canopy;
    canopy.shape = Shape::Ellipsoid;
    canopy.material = Material::Leaves;
    canopy.origin = {x, y, trunk_height + vertical_radius};
    canopy.extent_u = canopy_radius;
    canopy.extent_v = vertical_radius;
    canopy.look.base = jittered(rng, kLeafColours[rng.index(kLeafColours.size())], 0.1);
    canopy.noise_key = rng.next();
    // Mean of the pairwise axis products: exact for a sphere, within 2% for these spheroids;
    // it only shares out the budget.
    canopy.area = 4 * kPi * (canopy_radius * canopy_radius + 2 * canopy_radius * vertical_radius) / 3;
    layout.surfaces.push_back(canopy);
}

bool near_junction(double along) {
    for (double c : kRoadCentres)
        if (std::abs(along - c) < kRoadsideOffset + kStreetCanopyMax) return true;
    return false;
}

// 1, 2 or 4 buildings on a lot, set back from its edges; tiny parcels stay open plaza.
void plan_buildings(Rng& rng, double x0, double x1, double y0, double y1, std::vector<Footprint>& out) {
    std::vector<double> xs{x0, x1}, ys{y0, y1};
    if (rng.chance(kSplitChance)) xs.insert(xs.begin() + 1, x0 + (x1 - x0) * rng.uniform(0.4, 0.6));
    if (rng.chance(kSplitChance)) ys.insert(ys.begin() + 1, y0 + (y1 - y0) * rng.uniform(0.4, 0.6));
    for (std::size_t b = 0; b + 1 < ys.size(); ++b)
        for (std::size_t a = 0; a + 1 < xs.size(); ++a) {
            const double setback = rng.uniform(kMinSetback, kMaxSetback);
            // Squared uniform: mostly low-rise, a few towers.
            const double u = rng.uniform();
            const Footprint f{xs[a] + setback, ys[b] + setback, xs[a + 1] - setback, ys[b + 1] - setback,
                              kMinBuildingHeight + (kMaxBuildingHeight - kMinBuildingHeight) * u * u};
            if (f.x1 - f.x0 >= kMinFootprint && f.y1 - f.y0 >= kMinFootprint) out.push_back(f);
        }
}

}  // namespace

Layout make_layout(std::uint64_t seed) {
    Layout layout;
    Rng rng(stream_key(seed, kLayoutStream));
    layout.noise_key = stream_key(seed, kNoiseStream);
    layout.lots = lot_spans();
    layout.surfaces.push_back(rect(Material::Ground, {-kGroundHalfExtent, -kGroundHalfExtent, 0}, {1, 0, 0}, {0, 1, 0},
                                   2 * kGroundHalfExtent, 2 * kGroundHalfExtent));

    for (bool& p : layout.park) p = rng.chance(kParkChance);
    if (std::none_of(layout.park.begin(), layout.park.end(), [](bool p) { return p; }))
        layout.park[rng.index(layout.park.size())] = true;

    // Ground, buildings, trees: each category is one run of surfaces (see share_out).
    std::vector<Footprint> buildings;
    for (std::size_t j = 0; j < kLotsPerAxis; ++j)
        for (std::size_t i = 0; i < kLotsPerAxis; ++i)
            if (!layout.park[j * kLotsPerAxis + i])
                plan_buildings(rng, layout.lots[i].first, layout.lots[i].second, layout.lots[j].first,
                               layout.lots[j].second, buildings);
    // One tower always reaches the maximum height, so every seed spans the same heights.
    if (!buildings.empty())
        std::max_element(buildings.begin(), buildings.end(), [](const Footprint& a, const Footprint& b) {
            return a.height < b.height;
        })->height = kMaxBuildingHeight;
    for (const Footprint& f : buildings) add_building(layout, rng, f);

    for (std::size_t j = 0; j < kLotsPerAxis; ++j)
        for (std::size_t i = 0; i < kLotsPerAxis; ++i) {
            if (!layout.park[j * kLotsPerAxis + i]) continue;
            const auto [x0, x1] = layout.lots[i];
            const auto [y0, y1] = layout.lots[j];
            const auto trees = static_cast<int>((x1 - x0) * (y1 - y0) / kParkAreaPerTree * rng.uniform(0.7, 1.0));
            for (int t = 0; t < trees; ++t)
                add_tree(layout, rng, rng.uniform(x0 + kParkTreeMargin, x1 - kParkTreeMargin),
                         rng.uniform(y0 + kParkTreeMargin, y1 - kParkTreeMargin), rng.uniform(2.5, 5.0));
        }
    for (bool street_along_x : {true, false})
        for (double c : kRoadCentres)
            for (double side : {-1.0, 1.0})
                for (double along = -kGroundHalfExtent + kStreetTreeSpacing / 2;
                     along < kGroundHalfExtent - kStreetCanopyMax - 1.0; along += kStreetTreeSpacing) {
                    const double at = along + rng.symmetric();
                    const double across = c + side * kStreetTreeOffset;
                    const double radius = rng.uniform(2.0, kStreetCanopyMax);
                    if (near_junction(at) || rng.chance(kStreetTreeGapChance)) continue;
                    if (street_along_x)
                        add_tree(layout, rng, at, across, radius);
                    else
                        add_tree(layout, rng, across, at, radius);
                }
    return layout;
}

// Exactly `budget` Gaussians over surfaces [begin, end), in proportion to area: surface i
// gets floor(budget * A_<=i / A) - floor(budget * A_<i / A), which sums to budget.
void share_out(std::vector<Surface>& surfaces, std::size_t begin, std::size_t end, std::uint64_t budget) {
    double total = 0;
    for (std::size_t i = begin; i < end; ++i) total += surfaces[i].area;
    double cumulative = 0;
    std::uint64_t given = 0;
    for (std::size_t i = begin; i < end; ++i) {
        cumulative += surfaces[i].area;
        const auto upto = i + 1 == end ? budget
                                       : std::min(budget, static_cast<std::uint64_t>(std::floor(
                                                              static_cast<double>(budget) * cumulative / total)));
        surfaces[i].count = upto - given;
        given = upto;
    }
}

// Rows as square as the count allows. Every row is filled edge to edge, so no surface
// has a gap however the count divides.
void plan_rows(Surface& s, double length_u, double length_v) {
    s.length_u = length_u;
    if (s.count == 0) return;
    const double ideal = std::sqrt(static_cast<double>(s.count) * length_v / length_u);
    s.rows = std::clamp<std::uint64_t>(static_cast<std::uint64_t>(ideal + 0.5), 1, s.count);
    s.dv = length_v / static_cast<double>(s.rows);
}

}  // namespace catgs::city
