// The built-in city's shared model, for its two halves: the layout (builtin_city_layout.cpp:
// roads, lots, buildings and trees as surfaces) and the per-Gaussian generation
// (builtin_city.cpp). Every file that includes this one must be built with
// -ffp-contract=off (renderer/CMakeLists.txt), or the city stops being bit-identical
// across machines (see builtin_city.cpp).
#pragma once

#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

#include "catgs/constants.hpp"
#include "catgs/math.hpp"

namespace catgs::city {

using V3 = Vec3<double>;

// ---------------------------------------------------------------------------------------
// Deterministic numbers

inline constexpr std::uint64_t kGolden = 0x9E3779B97F4A7C15ull;

inline std::uint64_t mix64(std::uint64_t z) {
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

inline double unit_from_bits(std::uint64_t bits) {
    return static_cast<double>(bits >> 11) * 0x1.0p-53;
}

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
inline constexpr std::uint64_t kLayoutStream = 0x6C61796F7574ull;
inline constexpr std::uint64_t kNoiseStream = 0x6E6F697365ull;
inline constexpr std::uint64_t kGaussianStream = 0x676175737331ull;

inline std::uint64_t stream_key(std::uint64_t seed, std::uint64_t stream) {
    return mix64(mix64(seed) ^ stream);
}

// ---------------------------------------------------------------------------------------
// Vectors, frames, quaternions

inline V3 cross(const V3& a, const V3& b) {
    return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline V3 normalised(const V3& a) {
    return (1.0 / std::sqrt(dot(a, a))) * a;
}

using Quat = std::array<double, 4>;  // (w, x, y, z)

// ---------------------------------------------------------------------------------------
// View dependence

inline constexpr int kShRestCoefficients = sh_coefficient_count(kMaxShDegree) - 1;
using ShLobe = std::array<double, kShRestCoefficients>;

// ---------------------------------------------------------------------------------------
// Layout

struct Rgb {
    double r, g, b;
};
inline Rgb operator*(double s, Rgb c) {
    return {s * c.r, s * c.g, s * c.b};
}

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
inline constexpr double kGroundHalfExtent = 100.0;
// Three streets each way cut the block into 4 x 4 lots of 31-42 m: room for 1-4 buildings.
inline constexpr std::array<double, 3> kRoadCentres{-60.0, 0.0, 60.0};
inline constexpr double kRoadHalfWidth = 6.0;  // two 3.5 m lanes plus parking strips
inline constexpr double kSidewalkWidth = 3.0;
inline constexpr double kRoadsideOffset = kRoadHalfWidth + kSidewalkWidth;  // where lots begin
inline constexpr std::size_t kLotsPerAxis = kRoadCentres.size() + 1;
// The parapet: a roof's rim, in the colour of the walls.
inline constexpr double kParapetWidth = 0.8;

using LotSpans = std::array<std::pair<double, double>, kLotsPerAxis>;

struct Layout {
    std::vector<Surface> surfaces;
    LotSpans lots{};  ///< the same spans in x and in y
    std::array<bool, kLotsPerAxis * kLotsPerAxis> park{};
    std::uint64_t noise_key = 0;
};

/// The surfaces of the city of `seed`, ground first, then buildings, then trees (each
/// category one run: share_out gives each its budget).
Layout make_layout(std::uint64_t seed);

/// Exactly `budget` Gaussians over surfaces [begin, end), in proportion to their area.
void share_out(std::vector<Surface>& surfaces, std::size_t begin, std::size_t end, std::uint64_t budget);

/// Rows of a Rect or Cylinder surface of length_u x length_v for its count.
void plan_rows(Surface& s, double length_u, double length_v);

}  // namespace catgs::city
