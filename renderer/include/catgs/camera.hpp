// Pinhole cameras. Conventions follow COLMAP / graphdeco 3DGS: camera axes +x right,
// +y down, +z forward (the viewing direction); the pose maps world to camera,
// x_cam = R * x_world + t. Pixel (i, j) is sampled at (i + 0.5, j + 0.5), and a camera
// point projects to (fx * x/z + cx, fy * y/z + cy).
#pragma once

#include <array>
#include <string>

namespace catgs {

struct Intrinsics {
    double fx = 0, fy = 0, cx = 0, cy = 0;
    int width = 0, height = 0;
};

/// World-to-camera rigid transform, in double: the world may be UTM-sized.
struct Pose {
    std::array<double, 9> rotation{1, 0, 0, 0, 1, 0, 0, 0, 1};  ///< row-major R
    std::array<double, 3> translation{0, 0, 0};                 ///< t
};

struct Camera {
    Intrinsics intrinsics;
    Pose pose;
    std::string name;        ///< e.g. cameras.json img_name; empty for generated frames
    double timestamp = 0.0;  ///< seconds
};

/// Intrinsics with the principal point at the image centre and the horizontal field of view
/// given in degrees (square pixels).
Intrinsics intrinsics_from_fov(int width, int height, double fov_x_degrees);

/// Throws catgs::Error (prefixed with `what`) unless sizes are positive, focal lengths
/// finite and positive with fields of view within [kMinFieldOfViewDegrees,
/// kMaxFieldOfViewDegrees] (across the image's longer side for the lower end, its shorter side
/// for the upper), and the principal point finite (outside the image it is a crop).
void validate(const Intrinsics& intrinsics, const std::string& what);

/// Whether two cameras make the same image grid and projection (every field equal): what a
/// cost measured, or a tile record made, at one holds at the other.
bool same_intrinsics(const Intrinsics& a, const Intrinsics& b);

/// Camera centre in world coordinates: -R^T t.
std::array<double, 3> camera_centre(const Pose& pose);

/// Pose from a camera centre and a camera-to-world rotation (columns = camera axes in world),
/// the form cameras.json and our trajectory files use.
Pose pose_from_centre(const std::array<double, 3>& centre, const std::array<double, 9>& camera_to_world);

/// Pose from a camera-to-world quaternion (w, x, y, z) and a centre. The quaternion is
/// normalised; throws catgs::Error if its norm is zero or non-finite.
Pose pose_from_quaternion(const std::array<double, 3>& centre, const std::array<double, 4>& wxyz);

/// The camera-to-world quaternion (w, x, y, z) of a pose.
std::array<double, 4> camera_to_world_quaternion(const Pose& pose);

/// A camera at `eye` looking at `target`; `up` is the world's up direction, which appears
/// as -y (up in the image) in camera coordinates. Throws if eye == target or the viewing
/// direction is parallel to up.
Pose look_at(const std::array<double, 3>& eye, const std::array<double, 3>& target, const std::array<double, 3>& up);

}  // namespace catgs
