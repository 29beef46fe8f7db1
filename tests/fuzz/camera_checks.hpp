// Invariants of cameras returned by the camera readers and generators (camera.hpp,
// trajectory.hpp): valid intrinsics, a finite rigid pose, a finite timestamp.
#pragma once

#include <cmath>
#include <string>
#include <vector>

#include "catgs/camera.hpp"
#include "catgs/error.hpp"
#include "fuzz_util.hpp"

namespace catgs::fuzz {

inline void check_camera(const Camera& camera, const std::string& what) {
    try {
        validate(camera.intrinsics, what);
    } catch (const Error& e) {
        violation(std::string("invalid intrinsics accepted: ") + e.what());
    }
    require(std::isfinite(camera.timestamp), what + ": non-finite timestamp");
    const auto& r = camera.pose.rotation;
    for (double v : r) require(std::isfinite(v), what + ": non-finite rotation");
    for (double v : camera.pose.translation) require(std::isfinite(v), what + ": non-finite translation");
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
            const double d = r[3 * i] * r[3 * j] + r[3 * i + 1] * r[3 * j + 1] + r[3 * i + 2] * r[3 * j + 2];
            require(std::fabs(d - (i == j ? 1.0 : 0.0)) < 1e-6, what + ": rotation is not orthonormal");
        }
    const double det =
        r[0] * (r[4] * r[8] - r[5] * r[7]) - r[1] * (r[3] * r[8] - r[5] * r[6]) + r[2] * (r[3] * r[7] - r[4] * r[6]);
    require(det > 0, what + ": rotation is a reflection");
}

inline void check_cameras(const std::vector<Camera>& cameras, const std::string& what) {
    require(!cameras.empty(), what + ": no cameras and no error");
    for (std::size_t i = 0; i < cameras.size(); ++i) check_camera(cameras[i], what + " camera " + std::to_string(i));
}

}  // namespace catgs::fuzz
