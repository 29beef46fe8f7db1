// Two CUDA renderers that must draw the same pixels (a scheduling or copy choice that changes
// no image): both render the same frames, the 8-bit and float images are compared bit for bit,
// then a partial frame. GPU tests only.
#pragma once

#include <gtest/gtest.h>

#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "catgs/camera.hpp"
#include "catgs/image.hpp"
#include "catgs/partial_image.hpp"
#include "catgs/render_options.hpp"
#include "cuda_renderer.hpp"

namespace catgs::test {

/// Frames 0..frames-1 of `view` through `a` and `b`, each pair of images equal (the first
/// difference fails the test); then the partial frame of `partial_view`. Returns each frame's
/// stats, a's then b's.
inline std::vector<std::pair<FrameStats, FrameStats>> expect_same_renders(
    cuda::CudaRenderer<float>& a, cuda::CudaRenderer<float>& b, const RenderOptions& options,
    const std::function<Camera(int)>& view, int frames, const Camera& partial_view, const std::string& name) {
    std::vector<std::pair<FrameStats, FrameStats>> stats;
    for (int frame = 0; frame < frames; ++frame) {
        const Camera cam = view(frame);
        ImageRGB8 a8, b8;
        ImageF af, bf;
        const FrameStats sa = a.render(cam, options, &a8, &af);
        const FrameStats sb = b.render(cam, options, &b8, &bf);
        const std::string what = name + ", frame " + std::to_string(frame);
        EXPECT_EQ(a8.rgb, b8.rgb) << what;
        EXPECT_EQ(af.rgb, bf.rgb) << what;
        EXPECT_EQ(sa.pairs, sb.pairs) << what;
        stats.emplace_back(sa, sb);
        if (a8.rgb != b8.rgb || af.rgb != bf.rgb) return stats;
    }
    PartialImage pa, pb;
    a.render_partial(partial_view, options, pa);
    b.render_partial(partial_view, options, pb);
    EXPECT_EQ(pa.colour, pb.colour) << name << ", partial";
    EXPECT_EQ(pa.transmittance, pb.transmittance) << name << ", partial";
    EXPECT_EQ(pa.stopped, pb.stopped) << name << ", partial";
    return stats;
}

}  // namespace catgs::test
