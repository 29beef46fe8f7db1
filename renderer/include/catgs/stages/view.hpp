// The per-frame camera as the kernels see it: scene-relative and in the render precision T.
//
// The world-to-camera transform is x_cam = R x_world + t. With x_world = origin + p, where p
// is the float position stored relative to the scene origin, x_cam = R p + (R origin + t).
// R origin + t is formed in double on the host: for a UTM-sized scene both terms are ~10^6 m
// and cancel to the camera's distance from the scene, so nothing large ever enters float.
#pragma once

#include <array>

#include "catgs/camera.hpp"
#include "catgs/constants.hpp"
#include "catgs/hd.hpp"
#include "catgs/math.hpp"

namespace catgs {

template <typename T>
struct View {
    Mat3<T> rotation;     ///< world (= scene-relative) to camera
    Vec3<T> translation;  ///< R * origin + t: scene-relative to camera
    Vec3<T> centre;       ///< camera centre relative to the scene origin (for SH directions)
    T fx, fy, cx, cy;
    int width, height;
    int tiles_x, tiles_y;
    T near_plane;
    /// Jacobian clamp: x/z in [-clamp_left, clamp_right], y/z in [-clamp_top, clamp_bottom].
    /// gsplat's principal-point-aware form of graphdeco's 1.3 * tan(fov/2): the image edge
    /// plus 0.3 of the half-width tangent on each side.
    T clamp_left, clamp_right, clamp_top, clamp_bottom;
    /// The depth row of the world-to-camera rotation and the depth translation, in double in
    /// every precision: Projected::key_depth, the sort key, is computed from them.
    double depth_row[3];
    double depth_offset;
};

inline int tiles_for(int pixels) {
    return (pixels + kTileSize - 1) / kTileSize;
}

/// The Jacobian clamp region reaches this fraction of the image size past each image edge:
/// each side's clamp adds (kJacobianClampFactor - 1) = 0.3 of the half-width tangent, i.e.
/// f * 0.3 * (w / 2f) = 0.15 w pixels. Written out rather than derived, so that the bounds
/// below are the exact doubles 0.15 and 1.15.
inline constexpr double kClampRegionMargin = 0.15;
static_assert(kClampRegionMargin - (kJacobianClampFactor - 1.0) / 2 < 1e-12 &&
                  (kJacobianClampFactor - 1.0) / 2 - kClampRegionMargin < 1e-12,
              "the clamp region's margin follows kJacobianClampFactor");
static_assert(1.0 + kClampRegionMargin == 1.15, "the far bound is the double 1.15");

/// The largest |x/z| or |y/z| of the clamp region: a turn of the view moves an image point
/// inside it by at most f (1 + tangent^2) pixels per radian.
template <typename T>
CATGS_HD T max_clamp_tangent(const View<T>& v) {
    T tangent = v.clamp_left > v.clamp_right ? v.clamp_left : v.clamp_right;
    tangent = v.clamp_top > tangent ? v.clamp_top : tangent;
    tangent = v.clamp_bottom > tangent ? v.clamp_bottom : tangent;
    return tangent;
}

/// Is the image point p (pixels) inside the clamp region, the image plus kClampRegionMargin of
/// its size per side? Beyond it the projection's Jacobian is the clamp's, not the point's.
template <typename T>
CATGS_HD bool in_clamp_region(const View<T>& v, Vec2<T> p) {
    const T w = static_cast<T>(v.width), h = static_cast<T>(v.height);
    const T lo = static_cast<T>(-kClampRegionMargin), hi = static_cast<T>(1.0 + kClampRegionMargin);
    return p.x >= lo * w && p.x <= hi * w && p.y >= lo * h && p.y <= hi * h;
}

/// Builds the View of `camera` for a scene whose positions are relative to `origin`.
template <typename T>
View<T> make_view(const Camera& camera, const std::array<double, 3>& origin, double near_plane = kDefaultNearPlane) {
    const Intrinsics& k = camera.intrinsics;
    const auto& r = camera.pose.rotation;
    const auto& t = camera.pose.translation;
    View<T> v;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) v.rotation.m[i][j] = static_cast<T>(r[3 * i + j]);
    double tr[3];
    for (int i = 0; i < 3; ++i)
        tr[i] = r[3 * i] * origin[0] + r[3 * i + 1] * origin[1] + r[3 * i + 2] * origin[2] + t[i];
    v.translation = {static_cast<T>(tr[0]), static_cast<T>(tr[1]), static_cast<T>(tr[2])};
    for (int j = 0; j < 3; ++j) v.depth_row[j] = r[6 + j];
    v.depth_offset = tr[2];
    auto c = camera_centre(camera.pose);
    v.centre = {static_cast<T>(c[0] - origin[0]), static_cast<T>(c[1] - origin[1]), static_cast<T>(c[2] - origin[2])};
    v.fx = static_cast<T>(k.fx);
    v.fy = static_cast<T>(k.fy);
    v.cx = static_cast<T>(k.cx);
    v.cy = static_cast<T>(k.cy);
    v.width = k.width;
    v.height = k.height;
    v.tiles_x = tiles_for(k.width);
    v.tiles_y = tiles_for(k.height);
    v.near_plane = static_cast<T>(near_plane);
    const double slack = kJacobianClampFactor - 1.0;
    const double half_tan_x = 0.5 * k.width / k.fx, half_tan_y = 0.5 * k.height / k.fy;
    v.clamp_left = static_cast<T>(k.cx / k.fx + slack * half_tan_x);
    v.clamp_right = static_cast<T>((k.width - k.cx) / k.fx + slack * half_tan_x);
    v.clamp_top = static_cast<T>(k.cy / k.fy + slack * half_tan_y);
    v.clamp_bottom = static_cast<T>((k.height - k.cy) / k.fy + slack * half_tan_y);
    return v;
}

}  // namespace catgs
