// The Gaussian scene, held as structure-of-arrays so that every stage streams only the
// fields it needs, and so that the arrays copy to the GPU as they are.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "catgs/constants.hpp"

namespace catgs {

struct Bounds {
    std::array<double, 3> min{0, 0, 0};
    std::array<double, 3> max{0, 0, 0};
};

/// Positions are float offsets from a double-precision origin chosen at load (the centre of
/// the bounds): a UAV capture in UTM coordinates sits 10^6..10^7 m from the world origin,
/// where a float has a resolution of 0.06..1 m. Every per-frame computation is relative to
/// this origin (see camera.hpp, make_view).
struct Scene {
    std::array<double, 3> origin{0, 0, 0};
    std::vector<float> positions;  ///< 3 per Gaussian, world minus origin
    std::vector<float> scales;     ///< 3 per Gaussian, activated (exp of the stored log)
    std::vector<float> rotations;  ///< 4 per Gaussian, unit quaternion (w, x, y, z)
    std::vector<float> opacities;  ///< 1 per Gaussian, activated (sigmoid of the logit)
    /// sh_coefficient_count(sh_degree) * 3 per Gaussian, laid out [gaussian][coefficient][rgb].
    /// Coefficient 0 is the DC term f_dc.
    std::vector<float> sh;
    int sh_degree = 0;
    Bounds bounds;  ///< world coordinates (origin included)

    std::size_t count() const { return opacities.size(); }
    int sh_coefficients() const { return sh_coefficient_count(sh_degree); }
    std::size_t sh_floats_per_gaussian() const { return 3u * static_cast<std::size_t>(sh_coefficients()); }
    std::size_t bytes() const;

    /// Resizes every array for n Gaussians at the current SH degree.
    void resize(std::size_t n);
    /// Recomputes bounds from the positions (world = origin + position).
    void update_bounds();
    /// Moves the origin to the centre of the bounds, re-expressing positions relative to it.
    /// Positions are rebased in double so nothing is lost beyond the final float rounding.
    void recentre();
    /// Throws catgs::Error naming `what` if array sizes disagree with count() or the degree.
    void check_consistent(const std::string& what) const;
};

/// A one-line description: count, SH degree, bounds, origin and memory.
std::string describe(const Scene& scene);
/// The same, as a JSON object.
std::string describe_json(const Scene& scene);

}  // namespace catgs
