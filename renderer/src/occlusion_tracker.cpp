#include "catgs/occlusion_tracker.hpp"

#include <algorithm>
#include <cmath>

#include "catgs/cache.hpp"

namespace catgs {
std::optional<OcclusionMotion> OcclusionTracker::plan(const Camera& now, bool eligible) {
    if (!recorded_) return std::nullopt;
    if (skip_ > 0) {
        --skip_;
        return std::nullopt;
    }
    if (!eligible || !same_intrinsics(now.intrinsics, camera_.intrinsics)) return std::nullopt;
    const auto a = camera_centre(now.pose), b = camera_centre(camera_.pose);
    const OcclusionMotion m =
        occlusion_motion(rotation_angle(now.pose, camera_.pose), std::hypot(a[0] - b[0], a[1] - b[1], a[2] - b[2]),
                         std::max(now.intrinsics.fx, now.intrinsics.fy));
    if (!m.usable) return std::nullopt;
    return m;
}

void OcclusionTracker::rendered(const Camera& now, bool recorded, bool took_cut, bool missed) {
    recorded_ = recorded;
    if (recorded) camera_ = now;
    if (missed) {
        skip_ = backoff_;
        backoff_ = std::min(2 * backoff_, kOcclusionMaxBackoff);
    } else if (took_cut) {
        backoff_ = 1;
    }
}

std::vector<float> occlusion_cells(const std::vector<float>& recorded, const OcclusionPyramid& p,
                                   const OcclusionMotion& motion) {
    std::vector<float> cells(static_cast<std::size_t>(p.cells));
    for (int y = 0; y < p.height[0]; ++y)
        for (int x = 0; x < p.width[0]; ++x)
            cells[static_cast<std::size_t>(p.at(0, x, y))] =
                predicted_cut(recorded.data(), p.width[0], p.height[0], x, y, motion);
    for (int l = 1; l < p.levels; ++l)
        for (int y = 0; y < p.height[l]; ++y)
            for (int x = 0; x < p.width[l]; ++x)
                cells[static_cast<std::size_t>(p.at(l, x, y))] = pyramid_cell(p, cells.data(), l, x, y);
    return cells;
}

}  // namespace catgs
