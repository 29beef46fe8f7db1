// The host's 3-vector: std::array<double, 3>, the type that poses, camera centres and scene
// origins already have (camera.hpp, scene.hpp), in double because the world may be UTM-sized.
// Per-Gaussian and per-pixel code uses Vec3<T> (math.hpp) instead, which compiles for the
// device in the render precision.
#pragma once

#include <array>
#include <cmath>

namespace catgs {

using HostVec3 = std::array<double, 3>;

inline HostVec3 sub(const HostVec3& a, const HostVec3& b) {
    return {a[0] - b[0], a[1] - b[1], a[2] - b[2]};
}
inline HostVec3 scaled(const HostVec3& a, double s) {
    return {a[0] * s, a[1] * s, a[2] * s};
}
inline HostVec3 operator+(const HostVec3& a, const HostVec3& b) {
    return {a[0] + b[0], a[1] + b[1], a[2] + b[2]};
}
inline HostVec3 operator*(double s, const HostVec3& a) {
    return {s * a[0], s * a[1], s * a[2]};
}
inline double dot(const HostVec3& a, const HostVec3& b) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}
inline HostVec3 cross(const HostVec3& a, const HostVec3& b) {
    return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
inline double norm(const HostVec3& a) {
    return std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
}
inline double distance(const HostVec3& a, const HostVec3& b) {
    return norm(sub(a, b));
}

}  // namespace catgs
