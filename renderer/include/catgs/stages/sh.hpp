// Real spherical harmonics up to degree 3, the basis graphdeco 3DGS trains with.
#pragma once

#include "catgs/constants.hpp"
#include "catgs/hd.hpp"
#include "catgs/math.hpp"

namespace catgs {

// Normalisation constants of the real SH basis (degree 0..3), in graphdeco's sign convention.
// Scalars rather than arrays: namespace-scope arrays are host memory to nvcc.
inline constexpr double kShC0 = 0.28209479177387814;
inline constexpr double kShC1 = 0.4886025119029199;
inline constexpr double kShC2a = 1.0925484305920792;   // xy, yz, xz terms (sign per term below)
inline constexpr double kShC2b = 0.31539156525252005;  // 2z^2 - x^2 - y^2
inline constexpr double kShC2c = 0.5462742152960396;   // x^2 - y^2
inline constexpr double kShC3a = 0.5900435899266435;   // y(3x^2 - y^2), x(x^2 - 3y^2)
inline constexpr double kShC3b = 2.890611442640554;    // xyz
inline constexpr double kShC3c = 0.4570457994644658;   // y(4z^2 - x^2 - y^2), x(...)
inline constexpr double kShC3d = 0.3731763325901154;   // z(2z^2 - 3x^2 - 3y^2)
inline constexpr double kShC3e = 1.445305721320277;    // z(x^2 - y^2)

/// Colour of one Gaussian seen along `dir` (unit vector from the camera centre to the
/// Gaussian), with coefficient k (an RGB triple, DC first) read as coeff(k), k below
/// sh_coefficient_count(degree). Returns sum(basis * coefficient) + 0.5, clamped at >= 0 (not
/// above: output clamps).
template <typename T, typename Coefficient>
CATGS_HD Vec3<T> sh_colour_of(Coefficient coeff, int degree, Vec3<T> dir) {
    Vec3<T> c = static_cast<T>(kShC0) * coeff(0);
    if (degree > 0) {
        const T x = dir.x, y = dir.y, z = dir.z;
        const T c1 = static_cast<T>(kShC1);
        c = c - (c1 * y) * coeff(1) + (c1 * z) * coeff(2) - (c1 * x) * coeff(3);
        if (degree > 1) {
            const T xx = x * x, yy = y * y, zz = z * z, xy = x * y, yz = y * z, xz = x * z;
            c = c + (static_cast<T>(kShC2a) * xy) * coeff(4) + (static_cast<T>(-kShC2a) * yz) * coeff(5) +
                (static_cast<T>(kShC2b) * (2 * zz - xx - yy)) * coeff(6) + (static_cast<T>(-kShC2a) * xz) * coeff(7) +
                (static_cast<T>(kShC2c) * (xx - yy)) * coeff(8);
            if (degree > 2) {
                c = c + (static_cast<T>(-kShC3a) * y * (3 * xx - yy)) * coeff(9) +
                    (static_cast<T>(kShC3b) * xy * z) * coeff(10) +
                    (static_cast<T>(-kShC3c) * y * (4 * zz - xx - yy)) * coeff(11) +
                    (static_cast<T>(kShC3d) * z * (2 * zz - 3 * xx - 3 * yy)) * coeff(12) +
                    (static_cast<T>(-kShC3c) * x * (4 * zz - xx - yy)) * coeff(13) +
                    (static_cast<T>(kShC3e) * z * (xx - yy)) * coeff(14) +
                    (static_cast<T>(-kShC3a) * x * (xx - 3 * yy)) * coeff(15);
            }
        }
    }
    const T offset = static_cast<T>(kShColourOffset);
    // Clamped at 0 (graphdeco) and at kMaxShColour, with NaN (inf - inf of huge
    // coefficients) taken as 0, so no colour can make a pixel non-finite.
    const T top = static_cast<T>(kMaxShColour);
    auto clamp = [top](T v) { return v > T(0) ? (v < top ? v : top) : T(0); };
    return {clamp(c.x + offset), clamp(c.y + offset), clamp(c.z + offset)};
}

/// sh_colour_of from sh_coefficient_count(degree) RGB triples stored in order.
template <typename T>
CATGS_HD Vec3<T> sh_colour(const float* coefficients, int degree, Vec3<T> dir) {
    return sh_colour_of<T>(
        [coefficients](int k) {
            return Vec3<T>{static_cast<T>(coefficients[3 * k]), static_cast<T>(coefficients[3 * k + 1]),
                           static_cast<T>(coefficients[3 * k + 2])};
        },
        degree, dir);
}

}  // namespace catgs
