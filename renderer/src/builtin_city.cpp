// The built-in city: a seeded layout (roads, lots, buildings, trees) of several hundred
// surfaces, then every Gaussian as a pure function of (seed, its index). Because no Gaussian
// depends on another, the scene is the same for any thread count or chunk size, and the work
// splits into fixed chunks without any shared state.
//
// Bit-identical output on every machine: integers come from splitmix64, floats from those
// integers with +, -, *, /, sqrt and floor only (all correctly rounded in IEEE 754), and the
// few angles use the polynomial sincos below rather than libm, whose last bits may differ
// between library versions. The remaining assumption is that the compiler does not fuse
// a * b + c into an FMA: baseline x86-64 code has none, and building this file with
// -ffp-contract=off makes it hold on every target (aarch64, -march=native).
#include "catgs/builtin_city.hpp"
#include "catgs/builtin_spec.hpp"

#include <algorithm>
#include <array>
#include <atomic>
#include <charconv>
#include <cmath>
#include <cstddef>
#include <string_view>
#include <thread>
#include <utility>
#include <vector>

#include "catgs/camera.hpp"
#include "catgs/constants.hpp"
#include "catgs/error.hpp"
#include "catgs/math.hpp"

namespace catgs {
namespace detail {

}  // namespace detail

namespace {

using V3 = Vec3<double>;

// ---------------------------------------------------------------------------------------
// Spec parsing

constexpr std::string_view kBuiltinPrefix = "builtin:";
constexpr const char* kCityLabel = "generating builtin city";

// Integers written as 2e6 are accepted; above 2^53 a double no longer holds every integer,
// so the scientific form is refused there (plain digits still reach 2^64 - 1).
constexpr double kMaxExactInteger = 9007199254740992.0;

std::string join(const std::vector<std::string>& items) {
    std::string out;
    for (const auto& item : items) out += (out.empty() ? "" : ", ") + item;
    return out;
}

void check_city_count(const std::string& what, std::uint64_t gaussians) {
    if (gaussians < kCityMinGaussians || gaussians > kCityMaxGaussians)
        throw Error(what + ": gaussians " + std::to_string(gaussians) + " is outside [" +
                    std::to_string(kCityMinGaussians) + ", " + std::to_string(kCityMaxGaussians) + "]");
}

// ---------------------------------------------------------------------------------------
// Deterministic numbers

constexpr std::uint64_t kGolden = 0x9E3779B97F4A7C15ull;

std::uint64_t mix64(std::uint64_t z) {
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

double unit_from_bits(std::uint64_t bits) { return static_cast<double>(bits >> 11) * 0x1.0p-53; }

// splitmix64: tiny state, so one can be made per Gaussian from its index for free.
class Rng {
public:
    explicit Rng(std::uint64_t key) : state_(key) {}
    std::uint64_t next() { return mix64(state_ += kGolden); }
    double uniform() { return unit_from_bits(next()); }  ///< [0, 1)
    double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
    double symmetric() { return 2.0 * uniform() - 1.0; }  ///< [-1, 1)
    bool chance(double p) { return uniform() < p; }
    std::size_t index(std::size_t n) { return static_cast<std::size_t>(next() % n); }

private:
    std::uint64_t state_;
};

// Independent streams of one seed: the layout, the value noise and the per-Gaussian keys.
constexpr std::uint64_t kLayoutStream = 0x6C61796F7574ull;
constexpr std::uint64_t kNoiseStream = 0x6E6F697365ull;
constexpr std::uint64_t kGaussianStream = 0x676175737331ull;

std::uint64_t stream_key(std::uint64_t seed, std::uint64_t stream) { return mix64(mix64(seed) ^ stream); }


// sin and cos of 2*pi*turns. Reduced to [-pi/4, pi/4], where the Taylor series to x^13
// (sin) and x^14 (cos) is accurate to 1e-14, far below float resolution.
void sincos_turns(double turns, double& s, double& c) {
    const double quarter_turns = 4.0 * (turns - std::floor(turns));
    const double quadrant = std::floor(quarter_turns + 0.5);
    const double x = (quarter_turns - quadrant) * (0.5 * kPi);
    const double x2 = x * x;
    double sx = 1.0 / 6227020800.0;  // 1/13!
    for (double d : {-1.0 / 39916800.0, 1.0 / 362880.0, -1.0 / 5040.0, 1.0 / 120.0, -1.0 / 6.0, 1.0})
        sx = sx * x2 + d;
    sx *= x;
    double cx = -1.0 / 87178291200.0;  // -1/14!
    for (double d : {1.0 / 479001600.0, -1.0 / 3628800.0, 1.0 / 40320.0, -1.0 / 720.0, 1.0 / 24.0, -0.5, 1.0})
        cx = cx * x2 + d;
    switch (static_cast<int>(quadrant) & 3) {
        case 0: s = sx; c = cx; break;
        case 1: s = cx; c = -sx; break;
        case 2: s = -sx; c = -cx; break;
        default: s = -cx; c = sx; break;
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

double fraction(double x) { return x - std::floor(x); }

// ---------------------------------------------------------------------------------------
// Vectors, frames, quaternions

V3 cross(const V3& a, const V3& b) { return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x}; }
V3 normalised(const V3& a) { return (1.0 / std::sqrt(dot(a, a))) * a; }

using Quat = std::array<double, 4>;  // (w, x, y, z)

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
                             -0.4570457994644658, 1.445305721320277,  -0.5900435899266435};
constexpr int kShRestCoefficients = sh_coefficient_count(kMaxShDegree) - 1;
using ShLobe = std::array<double, kShRestCoefficients>;

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
// Layout

struct Rgb {
    double r, g, b;
};
Rgb operator*(double s, Rgb c) { return {s * c.r, s * c.g, s * c.b}; }

enum class Shape : std::uint8_t { Rect, Cylinder, Ellipsoid };
enum class Material : std::uint8_t { Ground, Facade, Roof, Metal, Bark, Leaves };

// Appearance chosen per building or tree; each material reads the fields it needs.
struct Look {
    Rgb base{0, 0, 0};    ///< wall, roof, metal, bark or leaves
    Rgb accent{0, 0, 0};  ///< glass (facade), parapet (roof)
    double floor_height = 0, window_spacing = 0, window_width = 0;
    bool solar = false;  ///< roof carries rows of solar panels
};

struct Surface {
    Shape shape = Shape::Rect;
    Material material = Material::Ground;
    // Rect: corner and unit axes with u x v = n, extents in metres. Cylinder: base centre,
    // extent_u = radius, extent_v = height. Ellipsoid: centre, extent_u = horizontal
    // radius, extent_v = vertical radius.
    V3 origin{0, 0, 0}, u{1, 0, 0}, v{0, 1, 0}, n{0, 0, 1};
    double extent_u = 0, extent_v = 0;
    Look look;
    std::uint64_t noise_key = 0;  ///< own noise, so walls of one building do not repeat
    double area = 0;

    std::uint64_t first = 0, count = 0;  ///< the Gaussians [first, first + count)
    // Placement of Rect and Cylinder: `rows` rows of height dv along v, each holding
    // floor(count / rows) or one more Gaussians evenly spaced over length_u.
    std::uint64_t rows = 1;
    double length_u = 0, dv = 0;
    Quat frame{1, 0, 0, 0};  ///< Rect only: the (u, v, n) frame
    ShLobe lobe{};           ///< Rect only: its normal is fixed
};

// City block: 200 x 200 m, enough to fill a 60-degree view from the default 80 m altitude
// and to survey in a few minutes at 8 m/s.
constexpr double kGroundHalfExtent = 100.0;
// Three streets each way cut the block into 4 x 4 lots of 31-42 m: room for 1-4 buildings.
constexpr std::array<double, 3> kRoadCentres{-60.0, 0.0, 60.0};
constexpr double kRoadHalfWidth = 6.0;  // two 3.5 m lanes plus parking strips
constexpr double kSidewalkWidth = 3.0;
constexpr double kRoadsideOffset = kRoadHalfWidth + kSidewalkWidth;  // where lots begin
constexpr std::size_t kLotsPerAxis = kRoadCentres.size() + 1;
// Road markings: 15 cm lines, 3 m dashes every 6 m, edge lines 0.6 m inside the kerb,
// zebra crossings of 0.5 m stripes just outside each junction.
constexpr double kLineHalfWidth = 0.075;
constexpr double kDashPeriod = 6.0;
constexpr double kEdgeLineOffset = kRoadHalfWidth - 0.6;
constexpr double kCrossingNear = 1.0, kCrossingFar = 4.0, kStripePeriod = 1.0;
constexpr double kPavingTile = 1.2, kPlazaTile = 2.5, kJointWidth = 0.06;

constexpr double kParkChance = 0.2;
constexpr double kSplitChance = 0.6;  // per axis: a lot holds 1, 2 or 4 buildings
constexpr double kMinSetback = 2.0, kMaxSetback = 4.0;
constexpr double kMinFootprint = 8.0;
constexpr double kMinBuildingHeight = 8.0, kMaxBuildingHeight = 60.0;
constexpr double kParapetWidth = 0.8;
constexpr int kMaxRoofUnits = 3;  // air-conditioning boxes on a roof
constexpr double kSolarPanelLength = 1.7, kSolarRowPeriod = 2.6;

constexpr double kParkAreaPerTree = 90.0;
constexpr double kParkTreeMargin = 4.0;
constexpr double kStreetTreeSpacing = 12.0;
constexpr double kStreetTreeOffset = kRoadHalfWidth + 0.5 * kSidewalkWidth;  // mid-sidewalk
constexpr double kStreetTreeGapChance = 0.25;
constexpr double kStreetCanopyMax = 3.2;
static_assert(kStreetTreeOffset + kStreetCanopyMax < kRoadsideOffset + kMinSetback,
              "street canopies must end before the nearest facade");

// Budget shares in percent; the ground takes the remainder.
constexpr std::uint64_t kBuildingPercent = 45, kTreePercent = 15;

const std::array<Rgb, 6> kWallColours{{{0.62, 0.61, 0.58},
                                       {0.76, 0.70, 0.58},
                                       {0.58, 0.32, 0.24},
                                       {0.85, 0.85, 0.82},
                                       {0.50, 0.55, 0.60},
                                       {0.80, 0.72, 0.55}}};
const std::array<Rgb, 4> kGlassColours{{{0.12, 0.18, 0.24}, {0.10, 0.22, 0.25}, {0.20, 0.22, 0.25}, {0.15, 0.15, 0.20}}};
const std::array<Rgb, 4> kRoofColours{{{0.35, 0.35, 0.35}, {0.25, 0.25, 0.27}, {0.55, 0.55, 0.52}, {0.30, 0.40, 0.25}}};
const std::array<Rgb, 4> kLeafColours{{{0.20, 0.38, 0.14}, {0.26, 0.42, 0.16}, {0.18, 0.32, 0.15}, {0.30, 0.40, 0.18}}};
constexpr Rgb kBark{0.33, 0.24, 0.16};
constexpr Rgb kMetal{0.70, 0.71, 0.72};
constexpr Rgb kAsphalt{0.22, 0.22, 0.23};
constexpr Rgb kMarking{0.88, 0.88, 0.84};
constexpr Rgb kKerbPaving{0.62, 0.61, 0.59};
constexpr Rgb kPlaza{0.68, 0.64, 0.56};
constexpr Rgb kGrass{0.25, 0.45, 0.18};
constexpr Rgb kSolarPanel{0.10, 0.13, 0.25};

using LotSpans = std::array<std::pair<double, double>, kLotsPerAxis>;

struct Layout {
    std::vector<Surface> surfaces;
    LotSpans lots{};  ///< the same spans in x and in y
    std::array<bool, kLotsPerAxis * kLotsPerAxis> park{};
    std::uint64_t noise_key = 0;
};

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

Rgb jittered(Rng& rng, Rgb c, double amount) { return (1.0 + amount * rng.symmetric()) * c; }

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

Layout make_layout(std::uint64_t seed) {
    Layout layout;
    Rng rng(stream_key(seed, kLayoutStream));
    layout.noise_key = stream_key(seed, kNoiseStream);
    layout.lots = lot_spans();
    layout.surfaces.push_back(rect(Material::Ground, {-kGroundHalfExtent, -kGroundHalfExtent, 0}, {1, 0, 0},
                                   {0, 1, 0}, 2 * kGroundHalfExtent, 2 * kGroundHalfExtent));

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
                for (double along = -kGroundHalfExtent + kStreetTreeSpacing / 2; along < kGroundHalfExtent - kStreetCanopyMax - 1.0;
                     along += kStreetTreeSpacing) {
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
                                       : std::min(budget, static_cast<std::uint64_t>(
                                                              std::floor(static_cast<double>(budget) * cumulative / total)));
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

// ---------------------------------------------------------------------------------------
// Per-Gaussian generation

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

double opaque(Rng& rng) { return rng.uniform(0.9, 0.98); }

bool on_line(double offset, double centre) { return std::abs(offset - centre) < kLineHalfWidth; }

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
    if (layout.park[j * kLotsPerAxis + i])
        return {(0.75 + 0.3 * coarse + 0.25 * fine) * kGrass, opaque(rng), 0.02};
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
    const bool window = away_from_corner && (ground_floor ? in_floor > 0.4 && in_floor < look.floor_height - 0.6 &&
                                                                in_bay > 0.2 && in_bay < look.window_spacing - 0.2
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

void write_gaussian(const Output& out, std::uint64_t i, const V3& p, const std::array<double, 3>& scale,
                    const Quat& q, const Appearance& look, const ShLobe& lobe) {
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
        case Material::Ground: look = ground_look(layout, p.x, p.y, rng); break;
        case Material::Facade: look = facade_look(s, a, b, rng); break;
        case Material::Roof: look = roof_look(s, a, b, rng); break;
        default: look = {(0.9 + 0.1 * rng.uniform()) * s.look.base, opaque(rng), 0.15}; break;  // roof units
    }
    write_gaussian(out, i, p, scale, spin_about_normal(s.frame, spin_c, spin_s), look, s.lobe);
}

constexpr std::uint64_t kChunkSize = 1u << 16;  // ~15 MB of output: fine-grained enough to balance 2..64 threads

}  // namespace

namespace detail {

std::string builtin_name(const std::string& spec) {
    if (spec.rfind(kBuiltinPrefix, 0) != 0)
        throw Error(spec + ": not a builtin spec (expected builtin:NAME?key=value&...)");
    const std::size_t query = spec.find('?');
    std::string name = spec.substr(kBuiltinPrefix.size(), query == std::string::npos ? std::string::npos
                                                                                      : query - kBuiltinPrefix.size());
    if (name.empty()) throw Error(spec + ": missing a name after 'builtin:'");
    return name;
}

SpecParams builtin_params(const std::string& spec, const std::vector<std::string>& known_keys) {
    SpecParams params;
    std::size_t begin = spec.find('?');
    if (begin == std::string::npos) return params;
    for (++begin;;) {
        const std::size_t end = std::min(spec.find('&', begin), spec.size());
        const std::string item = spec.substr(begin, end - begin);
        const std::size_t eq = item.find('=');
        if (item.empty()) throw Error(spec + ": empty parameter (a stray '?' or '&')");
        if (eq == std::string::npos) throw Error(spec + ": parameter '" + item + "' is missing '=' (expected key=value)");
        std::string key = item.substr(0, eq), value = item.substr(eq + 1);
        if (std::find(known_keys.begin(), known_keys.end(), key) == known_keys.end())
            throw Error(spec + ": unknown key '" + key + "' (available: " + join(known_keys) + ")");
        if (value.empty()) throw Error(spec + ": key '" + key + "' has an empty value");
        for (const auto& seen : params)
            if (seen.first == key) throw Error(spec + ": duplicate key '" + key + "'");
        params.emplace_back(std::move(key), std::move(value));
        if (end == spec.size()) return params;
        begin = end + 1;
    }
}

std::uint64_t spec_integer(const std::string& spec, const std::string& key, const std::string& value) {
    const char* first = value.data();
    const char* last = first + value.size();
    std::uint64_t integer = 0;
    if (auto [end, ec] = std::from_chars(first, last, integer); ec == std::errc() && end == last) return integer;
    double real = 0;
    if (auto [end, ec] = std::from_chars(first, last, real);
        ec == std::errc() && end == last && real >= 0 && real <= kMaxExactInteger && real == std::floor(real))
        return static_cast<std::uint64_t>(real);
    throw Error(spec + ": value '" + value + "' of '" + key + "' is not a non-negative integer");
}

double spec_number(const std::string& spec, const std::string& key, const std::string& value) {
    const char* first = value.data();
    const char* last = first + value.size();
    double real = 0;
    if (auto [end, ec] = std::from_chars(first, last, real); ec == std::errc() && end == last && std::isfinite(real))
        return real;
    throw Error(spec + ": value '" + value + "' of '" + key + "' is not a finite number");
}

Scene make_city_with_threads(const CityParams& params, const Progress& progress, unsigned threads) {
    check_city_count("builtin:city", params.gaussians);
    const std::uint64_t n = params.gaussians;

    Layout layout = make_layout(params.seed);
    auto& surfaces = layout.surfaces;
    const auto is_building = [](const Surface& s) {
        return s.material == Material::Facade || s.material == Material::Roof || s.material == Material::Metal;
    };
    const auto buildings_begin = static_cast<std::size_t>(
        std::find_if(surfaces.begin(), surfaces.end(), is_building) - surfaces.begin());
    const auto trees_begin = static_cast<std::size_t>(
        std::find_if(surfaces.begin() + static_cast<std::ptrdiff_t>(buildings_begin), surfaces.end(),
                     [&](const Surface& s) { return !is_building(s); }) -
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
