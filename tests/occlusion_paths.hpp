// The occlusion cut's test paths and scenes, shared by the CPU backend's tests
// (test_cpu_occlusion.cpp) and the CUDA backend's (gpu/test_cuda_occlusion.cpp), so that both
// backends face the same glide, jump and turn.
#pragma once

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <iostream>
#include <string>
#include <vector>

#include "catgs/render_options.hpp"
#include "test_util.hpp"

namespace catgs::test::occlusion {

/// The frame of the sideways jump past the scene's edge in path().
inline constexpr std::size_t kJumpFrame = 8;

/// A camera at `centre` turned by `yaw` radians about the vertical axis.
inline Camera turned_camera(int width, int height, std::array<double, 3> centre, double yaw) {
    Camera c = forward_camera(width, height, 70.0, centre);
    const double s = std::sin(yaw), k = std::cos(yaw);
    c.pose = pose_from_centre(centre, {k, 0, -s, 0, 1, 0, s, 0, k});
    return c;
}

/// A glide (small steps and turns: the cut should hold), a jump sideways past the scene's edge
/// (tiles that were opaque now see empty space: the cut must miss and the frame be drawn
/// again), a turn too wide for the cut, and a glide again.
inline std::vector<Camera> path(int width, int height) {
    std::vector<Camera> cameras;
    for (int f = 0; f < 8; ++f)
        cameras.push_back(turned_camera(width, height, {0.02 * f, 0.01 * f, 0.03 * f}, 0.001 * f));
    cameras.push_back(turned_camera(width, height, {4.5, 0.0, 0.2}, 0.0));
    cameras.push_back(turned_camera(width, height, {4.5, 0.0, 0.2}, 0.3));
    for (int f = 0; f < 4; ++f) cameras.push_back(turned_camera(width, height, {4.5 - 0.02 * f, 0.0, 0.2}, 0.3));
    return cameras;
}

/// Dense enough that the tiles turn opaque: `count` Gaussians in a 6 m box.
inline RandomSceneParams dense_scene(std::size_t count) {
    RandomSceneParams p;
    p.count = count;
    p.extent = 3.0;
    p.log_scale_min = -3.5;
    p.log_scale_max = -1.5;
    return p;
}

/// What a path rendered with the cut did, frame by frame.
struct PathCounts {
    std::uint64_t occluded = 0, redrawn = 0, frames_cut = 0;
    std::vector<FrameStats> stats;  // the cut's, a frame each
};

/// One frame with the cut (`cut`) against the same frame without it (`full`), the images
/// compared by the caller: the cut's counts add up to the full lists, the uncut frame has none.
inline void check_frame(const FrameStats& cut, const FrameStats& full, const std::string& frame, PathCounts& counts) {
    EXPECT_EQ(cut.key_frame, full.key_frame) << frame;
    EXPECT_EQ(full.occluded, 0u) << frame;
    EXPECT_FALSE(full.occlusion_redrawn) << frame;
    if (!cut.occlusion_redrawn) {
        EXPECT_EQ(cut.pairs + cut.occluded_pairs, full.pairs) << frame;
    } else {
        EXPECT_EQ(cut.pairs, full.pairs) << frame << ": the second pass draws every Gaussian";
    }
    EXPECT_EQ(cut.occluded > 0, cut.occluded_pairs > 0) << frame;
    counts.occluded += cut.occluded;
    counts.redrawn += cut.occlusion_redrawn;
    counts.frames_cut += cut.occluded > 0;
    counts.stats.push_back(cut);
}

inline void report(const PathCounts& counts, const std::string& what) {
    std::cout << "[occlusion] " << what << ": " << counts.frames_cut << " of " << counts.stats.size() << " frames cut, "
              << counts.occluded << " Gaussians left out, " << counts.redrawn << " redrawn" << std::endl;
}

}  // namespace catgs::test::occlusion
