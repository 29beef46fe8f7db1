// Small host-device vector and matrix types used by every per-Gaussian and per-pixel
// formula. GLM is used for host-side pose math; it is not used here because its
// defaulted constructors carry __host__ __device__ annotations that nvcc 13 warns about
// (error #20012 under -Werror), and the kernels need only these few operations.
// Matrices are row-major: m[r][c].
#pragma once

#include <cmath>

#include "catgs/hd.hpp"

namespace catgs {

template <typename T>
struct Vec2 {
    T x, y;
};

template <typename T>
struct Vec3 {
    T x, y, z;
};

template <typename T>
struct Mat3 {
    T m[3][3];
};

template <typename T>
CATGS_INLINE Vec3<T> operator+(Vec3<T> a, Vec3<T> b) {
    return {a.x + b.x, a.y + b.y, a.z + b.z};
}
template <typename T>
CATGS_INLINE Vec3<T> operator-(Vec3<T> a, Vec3<T> b) {
    return {a.x - b.x, a.y - b.y, a.z - b.z};
}
template <typename T>
CATGS_INLINE Vec3<T> operator*(T s, Vec3<T> a) {
    return {s * a.x, s * a.y, s * a.z};
}
template <typename T>
CATGS_INLINE T dot(Vec3<T> a, Vec3<T> b) {
    return a.x * b.x + a.y * b.y + a.z * b.z;
}

template <typename T>
CATGS_INLINE Vec3<T> operator*(const Mat3<T>& a, Vec3<T> v) {
    return {a.m[0][0] * v.x + a.m[0][1] * v.y + a.m[0][2] * v.z, a.m[1][0] * v.x + a.m[1][1] * v.y + a.m[1][2] * v.z,
            a.m[2][0] * v.x + a.m[2][1] * v.y + a.m[2][2] * v.z};
}

template <typename T>
CATGS_INLINE Mat3<T> operator*(const Mat3<T>& a, const Mat3<T>& b) {
    Mat3<T> r;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) r.m[i][j] = a.m[i][0] * b.m[0][j] + a.m[i][1] * b.m[1][j] + a.m[i][2] * b.m[2][j];
    return r;
}

template <typename T>
CATGS_INLINE Mat3<T> transpose(const Mat3<T>& a) {
    Mat3<T> r;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) r.m[i][j] = a.m[j][i];
    return r;
}

template <typename To, typename From>
CATGS_INLINE Vec3<To> cast(Vec3<From> v) {
    return {static_cast<To>(v.x), static_cast<To>(v.y), static_cast<To>(v.z)};
}

/// Rotation matrix of a unit quaternion (w, x, y, z).
template <typename T>
CATGS_INLINE Mat3<T> quat_to_matrix(T w, T x, T y, T z) {
    Mat3<T> r;
    r.m[0][0] = 1 - 2 * (y * y + z * z);
    r.m[0][1] = 2 * (x * y - w * z);
    r.m[0][2] = 2 * (x * z + w * y);
    r.m[1][0] = 2 * (x * y + w * z);
    r.m[1][1] = 1 - 2 * (x * x + z * z);
    r.m[1][2] = 2 * (y * z - w * x);
    r.m[2][0] = 2 * (x * z - w * y);
    r.m[2][1] = 2 * (y * z + w * x);
    r.m[2][2] = 1 - 2 * (x * x + y * y);
    return r;
}

// Precision-generic math: std:: overloads on the host (so float stays float), CUDA's
// overloaded math functions on the device.
#if defined(__CUDA_ARCH__)
#define CATGS_MATH_NS
#else
#define CATGS_MATH_NS std
#endif
template <typename T>
CATGS_INLINE T sqrt_of(T v) {
    return CATGS_MATH_NS::sqrt(v);
}
template <typename T>
CATGS_INLINE T exp_of(T v) {
    return CATGS_MATH_NS::exp(v);
}
template <typename T>
CATGS_INLINE T log_of(T v) {
    return CATGS_MATH_NS::log(v);
}
/// fabs: on the GPU a modifier of the instruction that reads it (-fabs(v) is one FADD).
template <typename T>
CATGS_INLINE T fabs_of(T v) {
    return CATGS_MATH_NS::fabs(v);
}
template <typename T>
CATGS_INLINE T floor_of(T v) {
    return CATGS_MATH_NS::floor(v);
}
template <typename T>
CATGS_INLINE T ceil_of(T v) {
    return CATGS_MATH_NS::ceil(v);
}
#undef CATGS_MATH_NS

/// |v|, keeping NaN as NaN.
template <typename T>
CATGS_INLINE T abs_of(T v) {
    return v < T(0) ? -v : v;
}

template <typename T>
CATGS_INLINE bool is_finite(T v) {
#if defined(__CUDA_ARCH__)
    return isfinite(v);
#else
    return std::isfinite(v);
#endif
}

}  // namespace catgs
