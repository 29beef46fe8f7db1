// Frame correctness: 30 poses of a UAV flight streamed in lock step; every decoded frame is
// compared with this test's own CPU renderer, fed the same cameras, hints and options in the
// same order (so its inter-frame cache makes the same decisions as the server's).
#include <cmath>

#include "server_test_util.hpp"

namespace catgs::test {
namespace {

constexpr int kFrames = 30;
/// JPEG at quality 90 on these images must stay above this PSNR against the exact render.
constexpr double kMinJpegPsnr = 35.0;

class FramesTest : public SharedServerTest<FramesTest> {
protected:
    /// Streams the path with `config` and checks every frame; `exact` or at least kMinJpegPsnr.
    void stream_and_compare(const v1::SessionConfig& config, bool exact, bool with_hints) {
        const auto path = uav_path(kFrames);
        server::SessionSetup setup;
        ASSERT_TRUE(server::parse_session_config(config, {}, "open", &setup).ok());
        auto reference = make_renderer("cpu", Precision::single, 2);
        reference->set_scene(test_scene());

        StreamClient client(channel_to(server_->port()));
        ASSERT_TRUE(client.open(config));
        std::uint64_t ack = 0;
        double worst_psnr = 1e9;
        int cached_frames = 0;
        for (int i = 0; i < kFrames; ++i) {
            v1::FrameRequest request = frame_request(static_cast<std::uint64_t>(i + 1), path[i], ack);
            if (with_hints && i + 1 < kFrames) {
                // Flight plan: the next two poses, plus a velocity from the path.
                for (int k = 1; k <= 2 && i + k < kFrames; ++k) {
                    auto* planned = request.add_flight_plan();
                    *planned->mutable_pose() = pose_of(path[i + k]);
                    planned->set_client_timestamp_us(static_cast<std::int64_t>(i + 1 + k) * 33'333);
                }
                const auto a = camera_centre(path[i].pose), b = camera_centre(path[i + 1].pose);
                request.mutable_linear_velocity()->set_x((b[0] - a[0]) * 30);
                request.mutable_linear_velocity()->set_y((b[1] - a[1]) * 30);
                request.mutable_linear_velocity()->set_z((b[2] - a[2]) * 30);
            }
            ASSERT_TRUE(client.send(request));
            v1::Frame frame;
            ASSERT_TRUE(client.stream->Read(&frame)) << "frame " << i;
            ASSERT_FALSE(frame.has_error()) << frame.error().message();
            ASSERT_EQ(frame.sequence(), request.sequence());
            ASSERT_EQ(frame.width(), static_cast<std::uint32_t>(kWidth));
            ASSERT_EQ(frame.height(), static_cast<std::uint32_t>(kHeight));
            EXPECT_EQ(frame.client_timestamp_us(), request.client_timestamp_us());
            EXPECT_GT(frame.cache().render_length(), 0u);
            EXPECT_EQ(frame.stats().frames_sent(), static_cast<std::uint64_t>(i + 1));
            EXPECT_GE(frame.timings().render_ms(), 0.0);
            if (!frame.cache().key_frame()) ++cached_frames;
            ack = frame.sequence();

            // The reference: same camera (from the same quaternion), same hints, same order.
            server::FrameSetup parsed;
            ASSERT_TRUE(server::parse_frame_request(request, setup.intrinsics, "frame", &parsed).ok());
            ImageRGB8 expected;
            const FrameStats stats =
                reference->render_rgb8(parsed.camera, setup.options, expected, parsed.hints ? &*parsed.hints : nullptr);
            EXPECT_EQ(stats.key_frame, frame.cache().key_frame()) << "frame " << i;
            const ImageRGB8 got = decode_frame(frame);
            ASSERT_EQ(got.width, kWidth);
            ASSERT_EQ(got.height, kHeight);
            if (exact) {
                ASSERT_EQ(got.rgb, expected.rgb) << "frame " << i << " differs from the reference render";
            } else {
                const ImageError error = compare(got, expected);
                worst_psnr = std::min(worst_psnr, error.psnr);
                EXPECT_GE(error.psnr, kMinJpegPsnr) << "frame " << i;
            }
        }
        EXPECT_TRUE(client.close().ok());
        if (!exact) std::printf("JPEG worst PSNR %.2f dB\n", worst_psnr);
        if (setup.options.catgs.cache != CacheMode::off)
            std::printf("%d of %d frames from the cache\n", cached_frames, kFrames);
    }
};

TEST_F(FramesTest, PngFramesAreExactWithTheSpeculativeCacheAndHints) {
    v1::SessionConfig config = session_config(v1::ENCODING_PNG);
    config.mutable_pipeline()->set_cache(v1::CACHE_MODE_SPECULATIVE);
    // Counted work, not time, chooses W: the reference renderer then plans the same frames.
    config.mutable_pipeline()->set_window_cost(v1::WINDOW_COST_WORK);
    stream_and_compare(config, true, true);
}

TEST_F(FramesTest, RawFramesAreExactWithoutCache) {
    v1::SessionConfig config = session_config(v1::ENCODING_RAW_RGB8);
    config.mutable_pipeline()->set_cache(v1::CACHE_MODE_OFF);
    config.mutable_background()->set_r(0.2f);
    config.mutable_background()->set_b(0.4f);
    stream_and_compare(config, true, false);
}

TEST_F(FramesTest, RawFramesAreExactWithFixedWindowAndSplit) {
    v1::SessionConfig config = session_config(v1::ENCODING_RAW_RGB8);
    config.mutable_pipeline()->set_cache(v1::CACHE_MODE_SPECULATIVE);
    config.mutable_pipeline()->set_fixed_window(4);
    config.mutable_pipeline()->set_split(v1::SPLIT_MODE_FIXED);
    config.mutable_pipeline()->set_split_k(64);
    config.mutable_pipeline()->set_culling(v1::CULLING_BBOX3SIGMA);
    // Counted work, not time: with time each renderer splits where its own timings say
    // splitting is faster (split_choice.hpp), and a split tile's sums can differ in the last bit.
    config.mutable_pipeline()->set_window_cost(v1::WINDOW_COST_WORK);
    stream_and_compare(config, true, false);
}

TEST_F(FramesTest, RawFramesAreExactWithTheReusedDepthOrder) {
    v1::SessionConfig config = session_config(v1::ENCODING_RAW_RGB8);
    config.mutable_pipeline()->set_cache(v1::CACHE_MODE_SPECULATIVE);
    config.mutable_pipeline()->set_reuse_depth_order(true);
    config.mutable_pipeline()->set_fixed_window(4);
    config.mutable_pipeline()->set_window_cost(v1::WINDOW_COST_WORK);  // as above: the same plan
    stream_and_compare(config, true, false);
}

TEST_F(FramesTest, JpegQuality90IsCloseToTheReference) {
    v1::SessionConfig config = session_config(v1::ENCODING_JPEG, 90);
    config.mutable_pipeline()->set_window_cost(v1::WINDOW_COST_WORK);  // as above: the same plan
    stream_and_compare(config, false, true);
}

// A hovering drone or a paused viewer repeats its pose: the server re-sends the last frame's
// bytes without rendering, and renders again as soon as the pose changes (by one ulp).
TEST_F(FramesTest, RepeatedPoseResendsTheLastFrameUnrendered) {
    const auto path = uav_path(3);
    StreamClient client(channel_to(server_->port()));
    ASSERT_TRUE(client.open(session_config(v1::ENCODING_PNG)));
    struct Step {
        int pose;     // index into path
        bool nudged;  // camera centre x one ulp further
        bool reused;  // expected
    };
    const std::vector<Step> requests = {{0, false, false}, {0, false, true}, {0, false, true},
                                        {1, false, false}, {1, true, false}, {1, true, true}};
    std::vector<v1::Frame> frames;
    std::uint64_t ack = 0;
    for (std::size_t i = 0; i < requests.size(); ++i) {
        v1::FrameRequest request = frame_request(i + 1, path[requests[i].pose], ack);
        auto* position = request.mutable_pose()->mutable_position();
        if (requests[i].nudged) position->set_x(std::nextafter(position->x(), 1e300));
        ASSERT_TRUE(client.send(request));
        v1::Frame frame;
        ASSERT_TRUE(client.stream->Read(&frame)) << "frame " << i;
        ASSERT_FALSE(frame.has_error()) << frame.error().message();
        ASSERT_EQ(frame.sequence(), i + 1);
        EXPECT_EQ(frame.cache().reused_previous(), requests[i].reused) << "frame " << i;
        if (requests[i].reused) {
            EXPECT_EQ(frame.data(), frames.back().data()) << "frame " << i;
            EXPECT_EQ(frame.cache().render_length(), 0u);
            EXPECT_EQ(frame.timings().render_ms(), 0.0);
        } else {
            EXPECT_GT(frame.cache().render_length(), 0u) << "frame " << i;
        }
        EXPECT_EQ(frame.stats().frames_sent(), i + 1);
        ack = frame.sequence();
        frames.push_back(std::move(frame));
    }
    EXPECT_EQ(frames.back().stats().frames_reused(), 3u);
    // The re-sent bytes are the frame the renderer draws for that pose.
    EXPECT_EQ(decode_frame(frames[2]).rgb, decode_frame(frames[0]).rgb);
    EXPECT_TRUE(client.close().ok());
}

TEST_F(FramesTest, PipelineOptionsMapOntoRenderOptions) {
    v1::SessionConfig config = session_config(v1::ENCODING_PNG);
    server::SessionSetup setup;
    ASSERT_TRUE(server::parse_session_config(config, {}, "open", &setup).ok());
    // Unset fields: the defaults every tool shares, the paper's cache with split k = 8192.
    EXPECT_EQ(setup.options.catgs.cache, CacheMode::speculative);
    EXPECT_TRUE(setup.options.catgs.adaptive_window);
    EXPECT_EQ(setup.options.culling, Culling::opacity_aware);
    EXPECT_FALSE(setup.options.catgs.resort_cached);
    EXPECT_FALSE(setup.options.catgs.split_auto);
    EXPECT_EQ(setup.options.catgs.split_k, kDefaultSplitK);
    EXPECT_DOUBLE_EQ(setup.options.catgs.guard_px, kDefaultGuardPx);
    EXPECT_DOUBLE_EQ(setup.options.catgs.reuse_order_max_angle, kDefaultReuseOrderMaxAngle);
    EXPECT_EQ(setup.options.catgs.cache, default_pipeline_options().catgs.cache);
    // Each default can be turned off explicitly.
    config.mutable_pipeline()->set_cache(v1::CACHE_MODE_OFF);
    config.mutable_pipeline()->set_reuse_depth_order(false);
    config.mutable_pipeline()->set_split(v1::SPLIT_MODE_OFF);
    ASSERT_TRUE(server::parse_session_config(config, {}, "open", &setup).ok());
    EXPECT_EQ(setup.options.catgs.cache, CacheMode::off);
    EXPECT_TRUE(setup.options.catgs.resort_cached);
    EXPECT_EQ(setup.options.catgs.split_k, 0u);
    EXPECT_FALSE(setup.options.catgs.split_auto);
    config.mutable_pipeline()->set_cache(v1::CACHE_MODE_SPECULATIVE);
    config.mutable_pipeline()->set_reuse_depth_order(true);
    config.mutable_pipeline()->set_fixed_window(8);
    config.mutable_pipeline()->set_split(v1::SPLIT_MODE_AUTO);
    config.mutable_pipeline()->set_culling(v1::CULLING_BBOX3SIGMA);
    config.mutable_pipeline()->set_near_plane(0.5);
    ASSERT_TRUE(server::parse_session_config(config, {}, "open", &setup).ok());
    EXPECT_EQ(setup.options.catgs.cache, CacheMode::speculative);
    EXPECT_FALSE(setup.options.catgs.resort_cached);
    EXPECT_FALSE(setup.options.catgs.adaptive_window);
    EXPECT_EQ(setup.options.catgs.window, 8);
    EXPECT_TRUE(setup.options.catgs.split_auto);
    EXPECT_EQ(setup.options.culling, Culling::bbox3sigma);
    EXPECT_DOUBLE_EQ(setup.options.near_plane, 0.5);
    config.mutable_pipeline()->set_split(v1::SPLIT_MODE_FIXED);
    config.mutable_pipeline()->set_split_k(300);
    config.mutable_pipeline()->set_reuse_order_max_degrees(180);  // the paper's cache
    ASSERT_TRUE(server::parse_session_config(config, {}, "open", &setup).ok());
    EXPECT_DOUBLE_EQ(setup.options.catgs.reuse_order_max_angle, kPi);
    EXPECT_FALSE(setup.options.catgs.split_auto);
    EXPECT_EQ(setup.options.catgs.split_k, 300u);
}

TEST_F(FramesTest, UnaryRenderMatchesTheReference) {
    const auto path = uav_path(5);
    const v1::RenderRequest request = render_request(session_config(v1::ENCODING_PNG), frame_request(7, path[3], 0));
    v1::Frame frame;
    const grpc::Status status = render_once(channel_to(server_->port()), request, &frame);
    ASSERT_TRUE(status.ok()) << status.error_message();
    EXPECT_EQ(frame.sequence(), 7u);

    server::SessionSetup setup;
    ASSERT_TRUE(server::parse_session_config(request.config(), {}, "config", &setup).ok());
    setup.options.catgs.cache = CacheMode::off;
    server::FrameSetup parsed;
    ASSERT_TRUE(server::parse_frame_request(request.frame(), setup.intrinsics, "frame", &parsed).ok());
    auto reference = make_renderer("cpu", Precision::single, 2);
    reference->set_scene(test_scene());
    ImageRGB8 expected;
    reference->render_rgb8(parsed.camera, setup.options, expected);
    EXPECT_EQ(decode_frame(frame).rgb, expected.rgb);
}

}  // namespace
}  // namespace catgs::test
