// preprocess: one Gaussian against one view. Culls, projects the mean, forms the 2D
// covariance by the EWA splatting approximation (Zwicker et al. 2002, eqs. 29/31, as in
// graphdeco 3DGS), inverts it to the conic, and evaluates the SH colour.
#pragma once

#include <cstdint>

#include "catgs/constants.hpp"
#include "catgs/hd.hpp"
#include "catgs/math.hpp"
#include "catgs/stages/sh.hpp"
#include "catgs/stages/view.hpp"

namespace catgs {

/// What the later stages need of one visible Gaussian.
template <typename T>
struct Projected {
    Vec2<T> mean;    ///< image position in pixels; pixel i is sampled at i + 0.5
    Vec3<T> conic;   ///< (a, b, c): upper triangle of the inverse 2D covariance
    Vec3<T> cov;     ///< (xx, xy, yy): the 2D covariance, blur included (for extents)
    Vec3<T> colour;  ///< RGB from SH, >= 0
    T opacity;       ///< activated opacity sigma
    T depth;         ///< view-space z, > near plane
    /// float(view-space z computed in double): the sort key, identical in every precision.
    /// Float depths of nearly coplanar neighbours (a road marking on asphalt, a facade seen at
    /// 45 degrees) land within one float ulp of each other and can swap order against the
    /// double reference, which changed single pixels by up to 35 levels on the built-in city.
    float key_depth;
};

/// The per-Gaussian inputs, as pointers into the Scene's arrays at index i.
struct GaussianRef {
    const float* position;  ///< 3
    const float* scale;     ///< 3
    const float* rotation;  ///< 4, (w, x, y, z), unit
    float opacity;
    const float* sh;  ///< sh_coefficient_count(degree) RGB triples
    int sh_degree;
};

/// 3D covariance Sigma = R S S^T R^T of a Gaussian (paper eq. 6), as a symmetric matrix.
template <typename T>
CATGS_HD Mat3<T> covariance_3d(const float* scale, const float* rotation) {
    const Mat3<T> r = quat_to_matrix<T>(rotation[0], rotation[1], rotation[2], rotation[3]);
    Mat3<T> m;  // M = R S
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) m.m[i][j] = r.m[i][j] * static_cast<T>(scale[j]);
    return m * transpose(m);
}

/// Projected::key_depth at `view` for a mean at `position`: view-space z summed in double in
/// the order of pc.z (Mat3 * Vec3 + translation), so the double renderer's keys are unchanged;
/// 3 double multiply-adds per Gaussian and pose. Defined behind the camera too: a cached
/// window keys every Gaussian it lists by its depth at the key pose, where one that enters
/// the view at a later pose may not be in front yet.
template <typename T>
CATGS_HD float key_depth_at(const View<T>& view, const float* position) {
    return static_cast<float>(view.depth_row[0] * static_cast<double>(position[0]) +
                              view.depth_row[1] * static_cast<double>(position[1]) +
                              view.depth_row[2] * static_cast<double>(position[2]) + view.depth_offset);
}

/// Projects one Gaussian's geometry: mean, 2D covariance, conic, depth, opacity (not its
/// colour). Returns false (culled) when it is at or behind the near plane, or when its 2D
/// covariance is degenerate or not finite; `out` is then unspecified. Tile counting needs
/// only this, so the SH colour is evaluated (shade_gaussian) only where a tile is touched.
template <typename T>
CATGS_HD bool project_geometry(const GaussianRef& g, const View<T>& view, Projected<T>& out) {
    const Vec3<T> p{static_cast<T>(g.position[0]), static_cast<T>(g.position[1]), static_cast<T>(g.position[2])};
    const Vec3<T> pc = view.rotation * p + view.translation;
    if (!(pc.z > view.near_plane)) return false;  // also rejects NaN
    // Done first, so that no double stays live through the covariance below.
    out.key_depth = key_depth_at(view, g.position);

    // Jacobian of the projection at the clamped direction: far off-screen Gaussians would
    // otherwise get 2D covariances dominated by the 1/z^2 terms.
    const T inv_z = T(1) / pc.z;
    T tx = pc.x * inv_z, ty = pc.y * inv_z;
    tx = tx < -view.clamp_left ? -view.clamp_left : (tx > view.clamp_right ? view.clamp_right : tx);
    ty = ty < -view.clamp_top ? -view.clamp_top : (ty > view.clamp_bottom ? view.clamp_bottom : ty);
    Mat3<T> j{};  // third row zero: only the upper-left 2x2 of the result is used
    j.m[0][0] = view.fx * inv_z;
    j.m[0][2] = -view.fx * tx * inv_z;
    j.m[1][1] = view.fy * inv_z;
    j.m[1][2] = -view.fy * ty * inv_z;

    // Sigma' = J W Sigma W^T J^T (EWA eq. 31) plus the low-pass blur b on the diagonal, formed
    // from the rows m0, m1 of M = J W R S as Sigma' = M M^T + b I, with
    //   det Sigma' = |m0 x m1|^2 + b (|m0|^2 + |m1|^2) + b^2   (Binet-Cauchy),
    // a sum of non-negative terms. cxx cyy - cxy^2 cancels catastrophically in float for a
    // nearly rank-one Sigma' (one huge axis, a needle seen end-on: det came out <= 0, culled,
    // or wrong by orders of magnitude), and R S S^T R^T loses the thin axes first. M is scaled
    // by 1/k (k = its largest entry, >= 1) so that det (~k^4) cannot overflow float for a
    // screen-filling Gaussian (the camera inside a 1e6 m one).
    const Mat3<T> r = quat_to_matrix<T>(static_cast<T>(g.rotation[0]), static_cast<T>(g.rotation[1]),
                                        static_cast<T>(g.rotation[2]), static_cast<T>(g.rotation[3]));
    Mat3<T> m = j * view.rotation * r;  // rows 0 and 1 are used
    T k = T(1);
    for (int i = 0; i < 2; ++i)
        for (int c = 0; c < 3; ++c) {
            m.m[i][c] *= static_cast<T>(g.scale[c]);
            const T a = m.m[i][c] < T(0) ? -m.m[i][c] : m.m[i][c];
            k = a > k ? a : k;  // a NaN entry leaves k alone and makes det NaN below
        }
    const T inv_k = T(1) / k;
    const Vec3<T> m0{m.m[0][0] * inv_k, m.m[0][1] * inv_k, m.m[0][2] * inv_k};
    const Vec3<T> m1{m.m[1][0] * inv_k, m.m[1][1] * inv_k, m.m[1][2] * inv_k};
    const Vec3<T> cross{m0.y * m1.z - m0.z * m1.y, m0.z * m1.x - m0.x * m1.z, m0.x * m1.y - m0.y * m1.x};
    const T blur = static_cast<T>(kCovarianceBlur) * inv_k * inv_k;
    const T sxx = dot(m0, m0) + blur, sxy = dot(m0, m1), syy = dot(m1, m1) + blur;  // Sigma' / k^2
    const T det = dot(cross, cross) + blur * (sxx + syy - blur);                    // det Sigma' / k^4
    if (!(det > T(0)) || !is_finite(det)) return false;
    const T inv_det = inv_k * inv_k / det;  // k^2 / det Sigma'

    out.mean = {view.fx * pc.x * inv_z + view.cx, view.fy * pc.y * inv_z + view.cy};
    out.conic = {syy * inv_det, -sxy * inv_det, sxx * inv_det};
    out.cov = {sxx * k * k, sxy * k * k, syy * k * k};  // may overflow to inf: extents only
    out.depth = pc.z;
    out.opacity = static_cast<T>(g.opacity);
    return is_finite(out.mean.x) && is_finite(out.mean.y) && is_finite(out.conic.x) && is_finite(out.conic.y) &&
           is_finite(out.conic.z);
}

/// The unit direction from the view's camera centre to the Gaussian, along which its SH colour
/// is seen (+z when they coincide).
template <typename T>
CATGS_HD Vec3<T> view_direction(const GaussianRef& g, const View<T>& view) {
    const Vec3<T> p{static_cast<T>(g.position[0]), static_cast<T>(g.position[1]), static_cast<T>(g.position[2])};
    const Vec3<T> dir = p - view.centre;
    const T len = sqrt_of(dot(dir, dir));
    return len > T(0) ? (T(1) / len) * dir : Vec3<T>{T(0), T(0), T(1)};
}

/// The SH colour of a Gaussian seen from the view's camera centre, its coefficient k read as
/// coeff(k) (sh_colour_of): for a caller that fetches the coefficients its own way.
template <typename T, typename Coefficient>
CATGS_HD void shade_gaussian_with(const GaussianRef& g, Coefficient coeff, const View<T>& view, Projected<T>& out) {
    out.colour = sh_colour_of<T>(coeff, g.sh_degree, view_direction(g, view));
}

/// The SH colour of a Gaussian seen from the view's camera centre.
template <typename T>
CATGS_HD void shade_gaussian(const GaussianRef& g, const View<T>& view, Projected<T>& out) {
    out.colour = sh_colour<T>(g.sh, g.sh_degree, view_direction(g, view));
}

/// Geometry and colour: everything the rasterizer needs of one Gaussian.
template <typename T>
CATGS_HD bool project_gaussian(const GaussianRef& g, const View<T>& view, Projected<T>& out) {
    if (!project_geometry(g, view, out)) return false;
    shade_gaussian(g, view, out);
    return true;
}

}  // namespace catgs
