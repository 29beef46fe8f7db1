// chunk_cull, chunk-level culling: a chunk (Scene::chunks, a box of means plus a footprint
// radius) is skipped without touching its Gaussians when no pose of the frame's window can
// see any of it. The test must never drop a Gaussian that some tile list would hold, so that
// culling chunks changes nothing in the image; it is conservative in three ways:
//  - The footprint of a Gaussian of largest scale s at depth z reaches at most
//    kChunkSigmas * s * sqrt(1 + tx^2 + ty^2) * f_max / z pixels from its mean (the largest
//    eigenvalue of J W Sigma W^T J^T, with |x/z| <= tx, |y/z| <= ty inside the Jacobian clamp
//    region; beyond it J is evaluated at the clamp). A mean outside a side plane of the clamp
//    region by more than that radius in metres is therefore farther than its footprint from
//    the image, in pixels: the sphere-to-plane distance d maps to at least f d / z.
//  - The side planes are those of the clamp region (graphdeco's 1.3 tan(fov/2)), widened by
//    kChunkMarginPx and the window's pixel guard; boxes grow by the translation guard, so a
//    Gaussian that the speculative planner must know about (uncached_can_enter) is kept too.
//  - Non-finite chunks have infinite boxes and NaN comparisons keep a chunk.
#pragma once

#include "catgs/constants.hpp"
#include "catgs/hd.hpp"
#include "catgs/math.hpp"
#include "catgs/scene.hpp"
#include "catgs/stages/view.hpp"

namespace catgs {

/// Whether any Gaussian of chunk `c` may touch a tile of `view` (or a tile within
/// `guard_px` pixels of rotation and `guard_translation` metres of camera motion of it).
template <typename T>
CATGS_HD bool chunk_may_be_visible(const Chunk& c, const View<T>& view, T guard_px, T guard_translation) {
    const T tx = view.clamp_left > view.clamp_right ? view.clamp_left : view.clamp_right;
    const T ty = view.clamp_top > view.clamp_bottom ? view.clamp_top : view.clamp_bottom;
    const T f_max = view.fx > view.fy ? view.fx : view.fy, f_min = view.fx > view.fy ? view.fy : view.fx;
    const T grow = static_cast<T>(c.radius) * sqrt_of(T(1) + tx * tx + ty * ty) * (f_max / f_min) + guard_translation;
    const Vec3<T> centre{(static_cast<T>(c.lo[0]) + static_cast<T>(c.hi[0])) * T(0.5),
                         (static_cast<T>(c.lo[1]) + static_cast<T>(c.hi[1])) * T(0.5),
                         (static_cast<T>(c.lo[2]) + static_cast<T>(c.hi[2])) * T(0.5)};
    Vec3<T> half{(static_cast<T>(c.hi[0]) - static_cast<T>(c.lo[0])) * T(0.5) + grow,
                 (static_cast<T>(c.hi[1]) - static_cast<T>(c.lo[1])) * T(0.5) + grow,
                 (static_cast<T>(c.hi[2]) - static_cast<T>(c.lo[2])) * T(0.5) + grow};
    const Mat3<T>& r = view.rotation;
    const Vec3<T> pc = r * centre + view.translation;
    // Rounding of the transform in T: a relative slack on the distances involved.
    const T slack = T(1e-5) * (abs_of(pc.x) + abs_of(pc.y) + abs_of(pc.z) + half.x + half.y + half.z);
    // The box lies outside the half-space n . x_cam >= offset (n in camera axes) when even its
    // farthest corner along n is below: n . pc + sum_j |(R^T n)_j| half_j < offset.
    auto outside = [&](T nx, T ny, T nz, T offset) {
        const T mx = r.m[0][0] * nx + r.m[1][0] * ny + r.m[2][0] * nz;
        const T my = r.m[0][1] * nx + r.m[1][1] * ny + r.m[2][1] * nz;
        const T mz = r.m[0][2] * nx + r.m[1][2] * ny + r.m[2][2] * nz;
        const T reach = nx * pc.x + ny * pc.y + nz * pc.z + abs_of(mx) * half.x + abs_of(my) * half.y +
                        abs_of(mz) * half.z + slack * (abs_of(nx) + abs_of(ny) + abs_of(nz));
        return reach < offset;
    };
    const T margin = static_cast<T>(kChunkMarginPx) + guard_px;
    const T left = view.clamp_left + margin / view.fx, right = view.clamp_right + margin / view.fx;
    const T top = view.clamp_top + margin / view.fy, bottom = view.clamp_bottom + margin / view.fy;
    // Near plane, then x/z >= -left, x/z <= right, y/z >= -top, y/z <= bottom.
    if (outside(T(0), T(0), T(1), view.near_plane)) return false;
    if (outside(T(1), T(0), left, T(0))) return false;
    if (outside(T(-1), T(0), right, T(0))) return false;
    if (outside(T(0), T(1), top, T(0))) return false;
    if (outside(T(0), T(-1), bottom, T(0))) return false;
    return true;
}

/// The chunk test over a speculative window: visible at any of its poses.
template <typename T>
CATGS_HD bool chunk_in_window(const Chunk& c, const View<T>* views, int window, T guard_px, T guard_translation) {
    for (int k = 0; k < window; ++k)
        if (chunk_may_be_visible(c, views[k], guard_px, guard_translation)) return true;
    return false;
}

}  // namespace catgs
