// The built-in city: a seeded layout (roads, lots, buildings, trees) of several hundred
// surfaces (builtin_city_layout.cpp), then every Gaussian as a pure function of (seed, its
// index), here. Because no Gaussian depends on another, the scene is the same for any thread
// count or chunk size, and the work splits into fixed chunks without any shared state.
//
// Bit-identical output on every machine: integers come from splitmix64, floats from those
// integers with +, -, *, /, sqrt and floor only (all correctly rounded in IEEE 754), and the
// few angles use the polynomial sincos below rather than libm, whose last bits may differ
// between library versions. The remaining assumption is that the compiler does not fuse
// a * b + c into an FMA: baseline x86-64 code has none, and building this file and the
// layout's with -ffp-contract=off makes it hold on every target (aarch64, -march=native).
#include "catgs/builtin_city.hpp"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstddef>
#include <thread>
#include <utility>
#include <vector>

#include "builtin_city_detail.hpp"
#include "catgs/builtin_spec.hpp"
#include "catgs/camera.hpp"
#include "catgs/constants.hpp"
#include "catgs/error.hpp"
#include "catgs/math.hpp"

namespace catgs {
namespace city {
namespace {

// sin and cos of 2*pi*turns. Reduced to [-pi/4, pi/4], where the Taylor series to x^13
// (sin) and x^14 (cos) is accurate to 1e-14, far below float resolution.
void sincos_turns(double turns, double& s, double& c) {
    const double quarter_turns = 4.0 * (turns - std::floor(turns));
    const double quadrant = std::floor(quarter_turns + 0.5);
    const double x = (quarter_turns - quadrant) * (0.5 * kPi);
    const double x2 = x * x;
    double sx = 1.0 / 6227020800.0;  // 1/13!
    for (double d : {-1.0 / 39916800.0, 1.0 / 362880.0, -1.0 / 5040.0, 1.0 / 120.0, -1.0 / 6.0, 1.0}) sx = sx * x2 + d;
    sx *= x;
    double cx = -1.0 / 87178291200.0;  // -1/14!
    for (double d : {1.0 / 479001600.0, -1.0 / 3628800.0, 1.0 / 40320.0, -1.0 / 720.0, 1.0 / 24.0, -0.5, 1.0})
        cx = cx * x2 + d;
    switch (static_cast<int>(quadrant) & 3) {
        case 0:
            s = sx;
            c = cx;
            break;
        case 1:
            s = cx;
            c = -sx;
            break;
        case 2:
            s = -sx;
            c = -cx;
            break;
        default:
            s = -cx;
            c = sx;
            break;
    }
}

// Value noise in [0, 1): smoothly interpolated hashes of a square lattice.
double lattice_value(std::uint64_t key, double i, double j) {
    const auto hi = static_cast<std::uint64_t>(static_cast<std::int64_t>(i));
    const auto hj = static_cast<std::uint64_t>(static_cast<std::int64_t>(j));
    return unit_from_bits(mix64(key ^ mix64(hi * 0xD6E8FEB86659FD93ull ^ hj * 0xA0761D6478BD642Full)));
}

double value_noise(std::uint64_t key, double x, double y, double cell) {
    const double fx = x / cell, fy = y / cell;
    const double ix = std::floor(fx), iy = std::floor(fy);
    const double tx = fx - ix, ty = fy - iy;
    const double sx = tx * tx * (3 - 2 * tx), sy = ty * ty * (3 - 2 * ty);
    const double a = lattice_value(key, ix, iy), b = lattice_value(key, ix + 1, iy);
    const double c = lattice_value(key, ix, iy + 1), d = lattice_value(key, ix + 1, iy + 1);
    return (a + (b - a) * sx) + ((c + (d - c) * sx) - (a + (b - a) * sx)) * sy;
}

double fraction(double x) {
    return x - std::floor(x);
}

// Rotation whose columns are (u, v, n): the Gaussian's scale axes in the world. Converted
// through camera_to_world_quaternion, whose pose stores that rotation transposed.
Quat frame_quaternion(const V3& u, const V3& v, const V3& n) {
    Pose frame;
    frame.rotation = {u.x, u.y, u.z, v.x, v.y, v.z, n.x, n.y, n.z};
    return camera_to_world_quaternion(frame);
}

// q * (c, 0, 0, s): a further rotation about the frame's third axis (the surface normal) by
// the angle whose half-angle cosine and sine are (c, s).
Quat spin_about_normal(const Quat& q, double c, double s) {
    return {q[0] * c - q[3] * s, q[1] * c + q[2] * s, q[2] * c - q[1] * s, q[0] * s + q[3] * c};
}

// ---------------------------------------------------------------------------------------
// View dependence

// Graphdeco's real SH constants and sign conventions, so the renderer evaluates exactly
// the basis functions the lobes are built from.
constexpr double kShC0 = 0.28209479177387814;
constexpr double kShC1 = 0.4886025119029199;
constexpr double kShC2[5] = {1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792,
                             0.5462742152960396};
constexpr double kShC3[7] = {-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154,
                             -0.4570457994644658, 1.445305721320277, -0.5900435899266435};

// A coefficient vector w_l * Y_lm(r) adds gloss * sum_l w_l (2l+1)/(4 pi) P_l(r . dir) to
// the colour: a lobe peaking (at 0.74 * gloss) when the view direction is r and dipping to
// -0.07 * gloss at right angles. Falling weights keep it broad, like a rough specular.
constexpr double kLobeWeight[4] = {0.0, 1.0, 0.7, 0.4};

ShLobe sh_lobe(const V3& r) {
    const double x = r.x, y = r.y, z = r.z, xx = x * x, yy = y * y, zz = z * z;
    const double w1 = kLobeWeight[1], w2 = kLobeWeight[2], w3 = kLobeWeight[3];
    return {w1 * -kShC1 * y,
            w1 * kShC1 * z,
            w1 * -kShC1 * x,
            w2 * kShC2[0] * x * y,
            w2 * kShC2[1] * y * z,
            w2 * kShC2[2] * (2 * zz - xx - yy),
            w2 * kShC2[3] * x * z,
            w2 * kShC2[4] * (xx - yy),
            w3 * kShC3[0] * y * (3 * xx - yy),
            w3 * kShC3[1] * x * y * z,
            w3 * kShC3[2] * y * (4 * zz - xx - yy),
            w3 * kShC3[3] * z * (2 * zz - 3 * xx - 3 * yy),
            w3 * kShC3[4] * x * (4 * zz - xx - yy),
            w3 * kShC3[5] * z * (xx - yy),
            w3 * kShC3[6] * x * (xx - 3 * yy)};
}

// Sun 60 degrees high toward +x +y: roofs and the ground catch a highlight from drone views.
const V3 kSun = normalised(V3{0.4, 0.3, 0.87});

// The renderer's SH direction is camera -> Gaussian. A surface lit by the sun is brightest
// seen from the mirror direction of the sun, i.e. for dir = -(2 (n.s) n - s). A surface in
// shadow gets a sheen toward its normal instead (brightest seen head-on), so it too
// changes with the view.
ShLobe surface_lobe(const V3& n) {
    const double ns = dot(n, kSun);
    return sh_lobe(ns > 0 ? kSun - (2 * ns) * n : -1.0 * n);
}

// ---------------------------------------------------------------------------------------
// Per-Gaussian generation

// Road markings: 15 cm lines, 3 m dashes every 6 m, edge lines 0.6 m inside the kerb,
// zebra crossings of 0.5 m stripes just outside each junction.
constexpr double kLineHalfWidth = 0.075;
constexpr double kDashPeriod = 6.0;
constexpr double kEdgeLineOffset = kRoadHalfWidth - 0.6;
constexpr double kCrossingNear = 1.0, kCrossingFar = 4.0, kStripePeriod = 1.0;
constexpr double kPavingTile = 1.2, kPlazaTile = 2.5, kJointWidth = 0.06;
constexpr double kSolarPanelLength = 1.7, kSolarRowPeriod = 2.6;

constexpr Rgb kAsphalt{0.22, 0.22, 0.23};
constexpr Rgb kMarking{0.88, 0.88, 0.84};
constexpr Rgb kKerbPaving{0.62, 0.61, 0.59};
constexpr Rgb kPlaza{0.68, 0.64, 0.56};
constexpr Rgb kGrass{0.25, 0.45, 0.18};
constexpr Rgb kSolarPanel{0.10, 0.13, 0.25};

// Budget shares in percent; the ground takes the remainder.
constexpr std::uint64_t kBuildingPercent = 45, kTreePercent = 15;

// Position jitter within a cell, as a fraction of the cell: enough to break up the grid's
// regularity (no moire at grazing views), little enough that neighbours stay close.
constexpr double kCellJitter = 0.2;
// In-plane standard deviation in cell sizes, with its own jitter. With these values no
// point of a surface seen face-on lets more than ~2.5% of the background through
// (GroundIsCoveredWithoutHoles measures it); at 0.65 it would be up to 18%.
constexpr double kCoverage = 0.8;
constexpr double kScaleJitter = 0.1;
// Surfaces are splats 12x thinner along the normal than along the surface.
constexpr double kFlatness = 12.0;
// Sine of the half-angle of the in-plane spin of surface splats (about 15 degrees): visibly
// irregular, yet a single Gaussian stretched over a long thin wall still covers it.
constexpr double kMaxSpin = 0.13;
// Leaf clumps: larger, semi-transparent, less flat, filling the outer third of the canopy
// with normals tilted up to about 30 degrees from the canopy's.
constexpr double kLeafCoverage = 0.9;
constexpr double kLeafFlatness = 5.0;
constexpr double kLeafMinOpacity = 0.3, kLeafMaxOpacity = 0.7;
constexpr double kCanopyDepth = 0.35;
constexpr double kLeafTilt = 0.55;
// 1 - 1/phi: successive Fibonacci-sphere points advance by the golden angle.
constexpr double kGoldenTurns = 0.3819660112501051;

struct Appearance {
    Rgb colour;
    double opacity;
    double gloss;  ///< peak of the view-dependent lobe, times 0.74
};

double opaque(Rng& rng) {
    return rng.uniform(0.9, 0.98);
}

bool on_line(double offset, double centre) {
    return std::abs(offset - centre) < kLineHalfWidth;
}

// Asphalt with markings, for a point `along` a road at `offset` from its centre line.
Rgb road_colour(double along, double offset) {
    double junction = kGroundHalfExtent * 4;  // distance past the nearest junction's edge
    for (double c : kRoadCentres) junction = std::min(junction, std::abs(along - c) - kRoadHalfWidth);
    if (junction > kCrossingNear && junction < kCrossingFar)
        return fraction(offset / kStripePeriod) < 0.5 && std::abs(offset) < kEdgeLineOffset ? kMarking : kAsphalt;
    const bool dash = on_line(offset, 0.0) && fraction(along / kDashPeriod) < 0.5;
    return dash || on_line(std::abs(offset), kEdgeLineOffset) ? kMarking : kAsphalt;
}

bool paving_joint(double x, double y, double tile) {
    return fraction(x / tile) < kJointWidth / tile || fraction(y / tile) < kJointWidth / tile;
}

Appearance ground_look(const Layout& layout, double x, double y, Rng& rng) {
    const double coarse = value_noise(layout.noise_key, x, y, 8.0);
    const double fine = value_noise(layout.noise_key ^ kGolden, x, y, 1.5);
    // Offsets from the centre line of the nearest street running along x, and along y.
    double from_x_street = kGroundHalfExtent * 4, from_y_street = from_x_street;
    for (double c : kRoadCentres) {
        if (std::abs(y - c) < std::abs(from_x_street)) from_x_street = y - c;
        if (std::abs(x - c) < std::abs(from_y_street)) from_y_street = x - c;
    }
    const double shade = 0.85 + 0.2 * coarse + 0.1 * fine;
    const bool on_x_street = std::abs(from_x_street) < kRoadHalfWidth;
    const bool on_y_street = std::abs(from_y_street) < kRoadHalfWidth;
    if (on_x_street || on_y_street) {
        const Rgb c = on_x_street && on_y_street ? kAsphalt  // junction boxes are unmarked
                      : on_x_street              ? road_colour(x, from_x_street)
                                                 : road_colour(y, from_y_street);
        return {shade * c, opaque(rng), 0.05};
    }
    if (std::abs(from_x_street) < kRoadsideOffset || std::abs(from_y_street) < kRoadsideOffset) {
        const double joint = paving_joint(x, y, kPavingTile) ? 0.8 : 1.0;
        return {(joint * shade) * kKerbPaving, opaque(rng), 0.03};
    }
    std::size_t i = 0, j = 0;
    while (i + 1 < kLotsPerAxis && x > layout.lots[i].second) ++i;
    while (j + 1 < kLotsPerAxis && y > layout.lots[j].second) ++j;
    if (layout.park[j * kLotsPerAxis + i]) return {(0.75 + 0.3 * coarse + 0.25 * fine) * kGrass, opaque(rng), 0.02};
    const double joint = paving_joint(x, y, kPlazaTile) ? 0.85 : 1.0;
    return {(joint * shade) * kPlaza, opaque(rng), 0.03};
}

// Windows in rows per floor; the ground floor has wide shop windows.
Appearance facade_look(const Surface& s, double a, double b, Rng& rng) {
    const Look& look = s.look;
    const double shade = 0.9 + 0.15 * value_noise(s.noise_key, a, b, 3.0);
    const double in_floor = fraction(b / look.floor_height) * look.floor_height;
    const double in_bay = fraction(a / look.window_spacing) * look.window_spacing;
    const double margin = 0.5 * (look.window_spacing - look.window_width);
    const bool away_from_corner = a > 1.0 && a < s.extent_u - 1.0;
    const bool ground_floor = b < look.floor_height;
    const bool window =
        away_from_corner && (ground_floor ? in_floor > 0.4 && in_floor < look.floor_height - 0.6 && in_bay > 0.2 &&
                                                in_bay < look.window_spacing - 0.2
                                          : in_floor > 0.9 && in_floor < 0.9 + 0.5 * look.floor_height &&
                                                in_bay > margin && in_bay < look.window_spacing - margin);
    if (window) return {(0.9 + 0.2 * rng.uniform()) * look.accent, rng.uniform(0.95, 0.99), 0.25};
    return {shade * look.base, opaque(rng), 0.04};
}

Appearance roof_look(const Surface& s, double a, double b, Rng& rng) {
    const Look& look = s.look;
    const double edge = std::min(std::min(a, s.extent_u - a), std::min(b, s.extent_v - b));
    if (edge < kParapetWidth) return {0.95 * look.accent, opaque(rng), 0.04};
    const double inner = kParapetWidth + 1.0;
    if (look.solar && edge > inner && fraction((b - inner) / kSolarRowPeriod) * kSolarRowPeriod < kSolarPanelLength)
        return {kSolarPanel, opaque(rng), 0.2};
    return {(0.85 + 0.3 * value_noise(s.noise_key, a, b, 2.0)) * look.base, opaque(rng), 0.08};
}

struct Output {
    float* positions;
    float* scales;
    float* rotations;
    float* opacities;
    float* sh;
    std::size_t sh_stride;
};

void write_gaussian(const Output& out, std::uint64_t i, const V3& p, const std::array<double, 3>& scale, const Quat& q,
                    const Appearance& look, const ShLobe& lobe) {
    const std::size_t g = static_cast<std::size_t>(i);
    out.positions[3 * g] = static_cast<float>(p.x);
    out.positions[3 * g + 1] = static_cast<float>(p.y);
    out.positions[3 * g + 2] = static_cast<float>(p.z);
    for (int a = 0; a < 3; ++a) out.scales[3 * g + a] = static_cast<float>(scale[a]);
    const double qn = 1.0 / std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    for (int a = 0; a < 4; ++a) out.rotations[4 * g + a] = static_cast<float>(q[a] * qn);
    out.opacities[g] = static_cast<float>(look.opacity);
    float* sh = out.sh + out.sh_stride * g;
    const double rgb[3] = {look.colour.r, look.colour.g, look.colour.b};
    for (int ch = 0; ch < 3; ++ch) {
        sh[ch] = static_cast<float>((rgb[ch] - kShColourOffset) / kShC0);
        // Highlights are mostly white, a little tinted by the surface.
        const double tint = look.gloss * (0.7 + 0.3 * rgb[ch]);
        for (int k = 0; k < kShRestCoefficients; ++k) sh[3 * (k + 1) + ch] = static_cast<float>(tint * lobe[k]);
    }
}

void emit(const Layout& layout, const Surface& s, std::uint64_t k, std::uint64_t i, Rng& rng, const Output& out) {
    if (s.shape == Shape::Ellipsoid) {
        // Fibonacci sphere: evenly spread directions for any count, then pushed inward.
        const double z = 1.0 - (2.0 * static_cast<double>(k) + 1.0) / static_cast<double>(s.count);
        const double ring = std::sqrt(std::max(0.0, 1.0 - z * z));
        double sn, cs;
        sincos_turns(static_cast<double>(k) * kGoldenTurns, sn, cs);
        const V3 dir{ring * cs, ring * sn, z};
        const double depth = 1.0 - kCanopyDepth * rng.uniform();
        const double a = s.extent_u, c = s.extent_v;
        const V3 p = s.origin + V3{depth * a * dir.x, depth * a * dir.y, depth * c * dir.z};
        const V3 outward = normalised(V3{dir.x / a, dir.y / a, dir.z / c});
        const V3 n = normalised(outward + kLeafTilt * V3{rng.symmetric(), rng.symmetric(), rng.symmetric()});
        const V3 side = cross(V3{0, 0, 1}, n);
        const V3 u = dot(side, side) > 1e-12 ? normalised(side) : V3{1, 0, 0};
        double spin_s, spin_c;
        sincos_turns(0.5 * rng.uniform(), spin_s, spin_c);  // any spin: leaves have no grain
        const Quat q = spin_about_normal(frame_quaternion(u, cross(n, u), n), spin_c, spin_s);
        const double spacing = std::sqrt(s.area / static_cast<double>(s.count));
        const double su = kLeafCoverage * spacing * (1 + kScaleJitter * rng.symmetric());
        const double sv = su * rng.uniform(0.6, 1.0);
        const Appearance look{(0.75 + 0.5 * rng.uniform()) * s.look.base, rng.uniform(kLeafMinOpacity, kLeafMaxOpacity),
                              0.04};
        write_gaussian(out, i, p, {su, sv, sv / kLeafFlatness}, q, look, surface_lobe(n));
        return;
    }

    // Rect and Cylinder: row r holds the Gaussians [start(r), start(r + 1)) with
    // start(r) = floor(r * count / rows); k lies in the last row that starts at or before it.
    const auto row_start = [&](std::uint64_t r) { return r * s.count / s.rows; };
    const std::uint64_t row = ((k + 1) * s.rows - 1) / s.count;
    const std::uint64_t in_row = row_start(row + 1) - row_start(row);
    const double du = s.length_u / static_cast<double>(in_row);
    const double a = (static_cast<double>(k - row_start(row)) + 0.5 + kCellJitter * rng.symmetric()) * du;
    const double b = (static_cast<double>(row) + 0.5 + kCellJitter * rng.symmetric()) * s.dv;
    const double su = kCoverage * du * (1 + kScaleJitter * rng.symmetric());
    const double sv = kCoverage * s.dv * (1 + kScaleJitter * rng.symmetric());
    const std::array<double, 3> scale{su, sv, std::min(su, sv) / kFlatness};
    const double spin_s = kMaxSpin * rng.symmetric(), spin_c = std::sqrt(1 - spin_s * spin_s);

    if (s.shape == Shape::Cylinder) {
        double sn, cs;
        sincos_turns(a / s.length_u, sn, cs);
        const V3 n{cs, sn, 0}, u{-sn, cs, 0}, up{0, 0, 1};
        const V3 p = s.origin + V3{s.extent_u * cs, s.extent_u * sn, b};
        const Appearance look{(0.85 + 0.3 * value_noise(s.noise_key, a, b, 0.5)) * s.look.base, opaque(rng), 0.02};
        write_gaussian(out, i, p, scale, spin_about_normal(frame_quaternion(u, up, n), spin_c, spin_s), look,
                       surface_lobe(n));
        return;
    }

    const V3 p = s.origin + a * s.u + b * s.v;
    Appearance look{};
    switch (s.material) {
        case Material::Ground:
            look = ground_look(layout, p.x, p.y, rng);
            break;
        case Material::Facade:
            look = facade_look(s, a, b, rng);
            break;
        case Material::Roof:
            look = roof_look(s, a, b, rng);
            break;
        default:
            look = {(0.9 + 0.1 * rng.uniform()) * s.look.base, opaque(rng), 0.15};
            break;  // roof units
    }
    write_gaussian(out, i, p, scale, spin_about_normal(s.frame, spin_c, spin_s), look, s.lobe);
}

constexpr std::uint64_t kChunkSize = 1u << 16;  // ~15 MB of output: fine-grained enough to balance 2..64 threads

}  // namespace
}  // namespace city

namespace {

// ---------------------------------------------------------------------------------------
// The city's spec and its limits (the builtin: syntax itself is builtin_spec.cpp)

constexpr const char* kCityLabel = "generating builtin city";

void check_city_count(const std::string& what, std::uint64_t gaussians) {
    if (gaussians < kCityMinGaussians || gaussians > kCityMaxGaussians)
        throw Error(what + ": gaussians " + std::to_string(gaussians) + " is outside [" +
                    std::to_string(kCityMinGaussians) + ", " + std::to_string(kCityMaxGaussians) + "]");
}

}  // namespace

namespace detail {

Scene make_city_with_threads(const CityParams& params, const Progress& progress, unsigned threads) {
    using namespace city;
    check_city_count("builtin:city", params.gaussians);
    const std::uint64_t n = params.gaussians;

    Layout layout = make_layout(params.seed);
    auto& surfaces = layout.surfaces;
    const auto is_building = [](const Surface& s) {
        return s.material == Material::Facade || s.material == Material::Roof || s.material == Material::Metal;
    };
    const auto buildings_begin =
        static_cast<std::size_t>(std::find_if(surfaces.begin(), surfaces.end(), is_building) - surfaces.begin());
    const auto trees_begin =
        static_cast<std::size_t>(std::find_if(surfaces.begin() + static_cast<std::ptrdiff_t>(buildings_begin),
                                              surfaces.end(), [&](const Surface& s) { return !is_building(s); }) -
                                 surfaces.begin());
    const std::uint64_t building_budget = n * kBuildingPercent / 100, tree_budget = n * kTreePercent / 100;
    share_out(surfaces, 0, buildings_begin, n - building_budget - tree_budget);
    share_out(surfaces, buildings_begin, trees_begin, building_budget);
    share_out(surfaces, trees_begin, surfaces.size(), tree_budget);

    std::uint64_t first = 0;
    for (Surface& s : surfaces) {
        s.first = first;
        first += s.count;
        if (s.shape == Shape::Rect) {
            plan_rows(s, s.extent_u, s.extent_v);
            s.frame = frame_quaternion(s.u, s.v, s.n);
            s.lobe = surface_lobe(s.n);
        } else if (s.shape == Shape::Cylinder) {
            plan_rows(s, 2 * kPi * s.extent_u, s.extent_v);
        }
    }

    Scene scene;
    scene.sh_degree = kMaxShDegree;
    scene.resize(static_cast<std::size_t>(n));
    const Output out{scene.positions.data(), scene.scales.data(), scene.rotations.data(),
                     scene.opacities.data(), scene.sh.data(),     scene.sh_floats_per_gaussian()};
    const std::uint64_t gaussian_key = stream_key(params.seed, kGaussianStream);
    const std::uint64_t chunks = (n + kChunkSize - 1) / kChunkSize;
    std::atomic<std::uint64_t> next_chunk{0}, chunks_done{0};

    // Only the calling thread reports progress: callers need not make Progress thread-safe.
    auto work = [&](bool report) {
        for (std::uint64_t c; (c = next_chunk.fetch_add(1)) < chunks;) {
            const std::uint64_t begin = c * kChunkSize, end = std::min(n, begin + kChunkSize);
            auto s = static_cast<std::size_t>(
                std::upper_bound(surfaces.begin(), surfaces.end(), begin,
                                 [](std::uint64_t i, const Surface& x) { return i < x.first; }) -
                surfaces.begin() - 1);
            for (std::uint64_t i = begin; i < end; ++i) {
                while (i >= surfaces[s].first + surfaces[s].count) ++s;
                Rng rng(mix64(gaussian_key + i));
                emit(layout, surfaces[s], i - surfaces[s].first, i, rng, out);
            }
            const std::uint64_t done = chunks_done.fetch_add(1) + 1;
            if (report && progress) progress(static_cast<double>(done) / static_cast<double>(chunks), kCityLabel);
        }
    };
    if (threads == 0) threads = std::max(1u, std::thread::hardware_concurrency());
    const auto helpers = static_cast<unsigned>(std::min<std::uint64_t>(threads, chunks) - 1);
    {
        std::vector<std::jthread> pool;
        for (unsigned t = 0; t < helpers; ++t) pool.emplace_back(work, false);
        work(true);
    }
    if (progress) progress(1.0, kCityLabel);
    scene.update_bounds();
    return scene;
}

}  // namespace detail

CityParams parse_city_spec(const std::string& spec) {
    const std::string name = detail::builtin_name(spec);
    if (name != "city") throw Error(spec + ": unknown generator '" + name + "' (available: city)");
    CityParams params;
    for (const auto& [key, value] : detail::builtin_params(spec, {"gaussians", "seed"}))
        (key == "gaussians" ? params.gaussians : params.seed) = detail::spec_integer(spec, key, value);
    check_city_count(spec, params.gaussians);
    return params;
}

Scene make_city(const CityParams& params, const Progress& progress) {
    return detail::make_city_with_threads(params, progress, 0);
}

}  // namespace catgs
