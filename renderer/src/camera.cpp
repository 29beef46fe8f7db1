#include "catgs/camera.hpp"

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>

#include "catgs/constants.hpp"
#include "catgs/error.hpp"
#include "catgs/host_vector.hpp"

namespace catgs {

Intrinsics intrinsics_from_fov(int width, int height, double fov_x_degrees) {
    Intrinsics k;
    k.width = width;
    k.height = height;
    k.fx = 0.5 * width / std::tan(0.5 * fov_x_degrees * kPi / 180.0);
    k.fy = k.fx;
    k.cx = 0.5 * width;
    k.cy = 0.5 * height;
    return k;
}

void validate(const Intrinsics& k, const std::string& what) {
    if (k.width <= 0 || k.height <= 0)
        throw Error(what + ": image size " + std::to_string(k.width) + "x" + std::to_string(k.height) +
                    " must be positive");
    if (k.width > kMaxImageSide || k.height > kMaxImageSide)
        throw Error(what + ": image size " + std::to_string(k.width) + "x" + std::to_string(k.height) +
                    " exceeds the largest supported side, " + std::to_string(kMaxImageSide));
    if (!(std::isfinite(k.fx) && std::isfinite(k.fy) && k.fx > 0 && k.fy > 0))
        throw Error(what + ": focal lengths fx=" + std::to_string(k.fx) + ", fy=" + std::to_string(k.fy) +
                    " must be finite and positive");
    // A finite focal length can still put every Gaussian in one pixel or spread one over the
    // sky (fx = 1e30 drew a blank frame). Each focal length's field of view is held within
    // [kMinFieldOfViewDegrees, kMaxFieldOfViewDegrees] across the image's longer side for the
    // lower end and its shorter side for the upper, so that --fov's whole range is valid on
    // any image shape (--fov 0.001 on 160 x 90 gives the 90 rows 0.00056 degrees).
    const auto fov_degrees = [](double size, double f) { return 2.0 * std::atan(size / (2.0 * f)) * 180.0 / kPi; };
    const int longer = std::max(k.width, k.height), shorter = std::min(k.width, k.height);
    for (const auto& [f, name] : {std::pair{k.fx, "fx"}, std::pair{k.fy, "fy"}}) {
        const double narrowest = fov_degrees(longer, f), widest = fov_degrees(shorter, f);
        if (!(narrowest >= kMinFieldOfViewDegrees))
            throw Error(what + ": focal length " + name + " " + format_number(f) + " gives a field of view of " +
                        format_number(narrowest) + " degrees across the image's " + std::to_string(longer) +
                        " px, below " + format_number(kMinFieldOfViewDegrees));
        if (!(widest <= kMaxFieldOfViewDegrees))
            throw Error(what + ": focal length " + name + " " + format_number(f) + " gives a field of view of " +
                        format_number(widest) + " degrees across the image's " + std::to_string(shorter) +
                        " px, above " + format_number(kMaxFieldOfViewDegrees));
    }
    // A principal point outside the image is a crop of a larger one (tests/test_stress.cpp
    // renders its 8192 x 8192 reference that way); only a non-finite one is refused.
    if (!(std::isfinite(k.cx) && std::isfinite(k.cy))) throw Error(what + ": principal point must be finite");
}

bool same_intrinsics(const Intrinsics& a, const Intrinsics& b) {
    return a.width == b.width && a.height == b.height && a.fx == b.fx && a.fy == b.fy && a.cx == b.cx && a.cy == b.cy;
}

std::array<double, 3> camera_centre(const Pose& p) {
    const auto& r = p.rotation;
    const auto& t = p.translation;
    return {-(r[0] * t[0] + r[3] * t[1] + r[6] * t[2]), -(r[1] * t[0] + r[4] * t[1] + r[7] * t[2]),
            -(r[2] * t[0] + r[5] * t[1] + r[8] * t[2])};
}

Pose pose_from_centre(const std::array<double, 3>& c, const std::array<double, 9>& c2w) {
    Pose p;
    // R = (camera-to-world)^T, t = -R c.
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) p.rotation[3 * i + j] = c2w[3 * j + i];
    for (int i = 0; i < 3; ++i)
        p.translation[i] = -(p.rotation[3 * i] * c[0] + p.rotation[3 * i + 1] * c[1] + p.rotation[3 * i + 2] * c[2]);
    return p;
}

Pose pose_from_quaternion(const std::array<double, 3>& centre, const std::array<double, 4>& q) {
    double n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    if (!std::isfinite(n) || n == 0.0) throw Error("camera quaternion has zero or non-finite norm");
    double w = q[0] / n, x = q[1] / n, y = q[2] / n, z = q[3] / n;
    std::array<double, 9> m{1 - 2 * (y * y + z * z), 2 * (x * y - w * z),     2 * (x * z + w * y),
                            2 * (x * y + w * z),     1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                            2 * (x * z - w * y),     2 * (y * z + w * x),     1 - 2 * (x * x + y * y)};
    return pose_from_centre(centre, m);
}

std::array<double, 4> camera_to_world_quaternion(const Pose& p) {
    // Camera-to-world matrix M = R^T; standard matrix-to-quaternion with the largest pivot.
    const auto& r = p.rotation;
    auto m = [&](int i, int j) { return r[3 * j + i]; };
    double tr = m(0, 0) + m(1, 1) + m(2, 2);
    double w, x, y, z;
    if (tr > 0) {
        double s = std::sqrt(tr + 1.0) * 2;
        w = 0.25 * s;
        x = (m(2, 1) - m(1, 2)) / s;
        y = (m(0, 2) - m(2, 0)) / s;
        z = (m(1, 0) - m(0, 1)) / s;
    } else if (m(0, 0) > m(1, 1) && m(0, 0) > m(2, 2)) {
        double s = std::sqrt(1.0 + m(0, 0) - m(1, 1) - m(2, 2)) * 2;
        w = (m(2, 1) - m(1, 2)) / s;
        x = 0.25 * s;
        y = (m(0, 1) + m(1, 0)) / s;
        z = (m(0, 2) + m(2, 0)) / s;
    } else if (m(1, 1) > m(2, 2)) {
        double s = std::sqrt(1.0 + m(1, 1) - m(0, 0) - m(2, 2)) * 2;
        w = (m(0, 2) - m(2, 0)) / s;
        x = (m(0, 1) + m(1, 0)) / s;
        y = 0.25 * s;
        z = (m(1, 2) + m(2, 1)) / s;
    } else {
        double s = std::sqrt(1.0 + m(2, 2) - m(0, 0) - m(1, 1)) * 2;
        w = (m(1, 0) - m(0, 1)) / s;
        x = (m(0, 2) + m(2, 0)) / s;
        y = (m(1, 2) + m(2, 1)) / s;
        z = 0.25 * s;
    }
    if (w < 0) {
        w = -w;
        x = -x;
        y = -y;
        z = -z;
    }
    return {w, x, y, z};
}

Pose look_at(const HostVec3& eye, const HostVec3& target, const HostVec3& up) {
    HostVec3 forward = sub(target, eye);
    double fn = norm(forward);
    if (!(fn > 0) || !std::isfinite(fn)) throw Error("look_at: eye and target coincide or are not finite");
    forward = scaled(forward, 1.0 / fn);
    // Camera +x (right) = forward x up; camera +y (down) = forward x right.
    HostVec3 right = cross(forward, up);
    double rn = norm(right);
    if (!(rn > 1e-12)) throw Error("look_at: viewing direction is parallel to the up vector");
    right = scaled(right, 1.0 / rn);
    HostVec3 down = cross(forward, right);
    std::array<double, 9> c2w{right[0],   down[0],  forward[0], right[1],  down[1],
                              forward[1], right[2], down[2],    forward[2]};
    return pose_from_centre(eye, c2w);
}

}  // namespace catgs
