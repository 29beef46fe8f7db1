// Limits (docs/limits-and-errors.md, "Limits"): message sizes, the client name, the pose rate,
// per-session renderer memory, the stall watchdog for clients that stop reading, and the
// renderer pool of unary renders.
#include <cstdio>

#include "fake_device.hpp"
#include "server_test_util.hpp"

namespace catgs::test {
namespace {

/// A client allowed to send big messages, so that the server's limit is what refuses them.
std::shared_ptr<grpc::Channel> big_sender(int port) {
    grpc::ChannelArguments args;  // not client_channel_args(): its 1 MiB send limit would win
    args.SetMaxReceiveMessageSize(net::kMaxFrameMessageBytes);
    args.SetMaxSendMessageSize(8 * 1024 * 1024);
    return channel_to(port, args);
}

TEST(ServerLimits, RequestsLargerThanTheReceiveLimitAreRefused) {
    auto server = start_server();
    BackgroundStream healthy(server->port());
    ASSERT_TRUE(healthy.advances(2));
    const std::string big(2 * 1024 * 1024, 'x');
    {
        StreamClient client(big_sender(server->port()));
        v1::SessionConfig config = session_config(v1::ENCODING_JPEG);
        config.set_client_name(big);
        client.open(config);
        const grpc::Status status = client.close();
        EXPECT_EQ(status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << status.error_message();
        EXPECT_NE(status.error_message().find("Received message larger than max"), std::string::npos)
            << status.error_message();
        EXPECT_NE(status.error_message().find("vs. 1048576)"), std::string::npos) << status.error_message();
    }
    {
        auto scenes = v1::SceneService::NewStub(big_sender(server->port()));
        grpc::ClientContext context;
        v1::LoadSceneRequest request;
        request.set_source(big);
        v1::SceneInfo info;
        const grpc::Status status = scenes->LoadScene(&context, request, &info);
        EXPECT_EQ(status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << status.error_message();
        EXPECT_NE(status.error_message().find("Received message larger than max"), std::string::npos)
            << status.error_message();
    }
    // Just below the limit passes the transport; the field checks then apply.
    {
        StreamClient client(big_sender(server->port()));
        v1::SessionConfig config = session_config(v1::ENCODING_JPEG);
        config.set_client_name(std::string(1000 * 1000, 'y'));
        client.open(config);
        const grpc::Status status = client.close();
        EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << status.error_message();
        EXPECT_EQ(status.error_message(), "open.client_name: 1000000 bytes; at most 256");
    }
    healthy.expect_kept_going();
}

/// Frame requests beyond max_pose_rate are not refused and not lost: the server reads them
/// later, so the client is slowed down by flow control, and StreamStats tells it so.
TEST(ServerLimits, PoseRateLimitSlowsAFastClientDown) {
    constexpr double kRate = 100;
    constexpr int kRequests = 250;  // 100 at once (the burst), the rest at 100/s: >= 1.5 s
    server::ServerOptions o = test_options();
    o.limits.max_pose_rate = kRate;
    auto server = start_server(o);
    const auto path = uav_path(kRequests);
    StreamClient client(channel_to(server->port()));
    ASSERT_TRUE(client.open(session_config(v1::ENCODING_JPEG)));
    std::atomic<std::uint64_t> last_sequence{0};
    v1::Frame last;
    std::thread reader([&] {
        for (v1::Frame f; client.stream->Read(&f);) {
            last_sequence = f.sequence();
            last = f;
        }
    });
    const auto begin = std::chrono::steady_clock::now();
    for (int i = 1; i <= kRequests; ++i)
        ASSERT_TRUE(client.send(
            frame_request(static_cast<std::uint64_t>(i), path[static_cast<std::size_t>(i - 1)], last_sequence)));
    client.stream->WritesDone();
    reader.join();
    const grpc::Status status = client.stream->Finish();
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - begin).count();
    std::printf("pose rate %.0f/s: %d requests took %.2f s; %llu reads delayed\n", kRate, kRequests, seconds,
                static_cast<unsigned long long>(server->stats().reads_delayed));
    EXPECT_TRUE(status.ok()) << status.error_message();
    EXPECT_GE(seconds, (kRequests - kRate) / kRate * 0.8);
    EXPECT_GT(server->stats().reads_delayed, 0u);
    // Every request was read (none dropped), and the newest pose rendered last.
    EXPECT_EQ(last.sequence(), static_cast<std::uint64_t>(kRequests));
    EXPECT_EQ(last.stats().requests_received(), static_cast<std::uint64_t>(kRequests));
    EXPECT_EQ(last.stats().frame_errors(), 0u);
    // The client sees that it was throttled: the stream's own count of delayed reads.
    EXPECT_GT(last.stats().frame_requests_delayed(), 0u);
    EXPECT_EQ(last.stats().frame_requests_delayed(), server->stats().reads_delayed);
}

/// Renderer memory per session (as the backend reports it; here a simulated device whose
/// arenas take 100 bytes per pixel): a session above max_session_bytes ends.
TEST(ServerLimits, SessionMemoryLimit) {
    auto device = std::make_shared<FakeDevice>(1'000'000'000, 100);
    server::ServerOptions o = test_options();
    o.renderer_factory = device->factory();
    o.limits.max_session_bytes = 4'000'000;  // 160x90 needs 1.44 MB, 320x180 5.76 MB
    auto server = start_server(o);
    ASSERT_NO_FATAL_FAILURE(expect_one_frame(channel_to(server->port())));
    ASSERT_TRUE(eventually([&] { return server->stats().pooled_renderers == 1; }));  // within the limit: kept
    const std::string expected =
        "max-session-memory: rendering scene 'city' at 320x180 needed 5760000 bytes of renderer memory; this server "
        "allows 4000000 per session; lower the resolution";
    {
        StreamClient client(channel_to(server->port()));
        v1::SessionConfig config = session_config(v1::ENCODING_JPEG);
        config.set_width(320);
        config.set_height(180);
        ASSERT_TRUE(client.open(config));
        client.send(frame_request(1, uav_path(2, 320, 180)[0], 0));
        const grpc::Status status = client.close();
        EXPECT_EQ(status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << status.error_message();
        EXPECT_EQ(status.error_message(), expected);
        // It took the pooled renderer and outgrew the limit: not given back.
        ASSERT_TRUE(eventually([&] { return server->stats().sessions_active == 0; }));
        EXPECT_EQ(server->stats().pooled_renderers, 0);
    }
    {
        v1::RenderRequest request =
            render_request(session_config(v1::ENCODING_PNG), frame_request(1, uav_path(2, 320, 180)[0], 0));
        request.mutable_config()->set_width(320);
        request.mutable_config()->set_height(180);
        v1::Frame frame;
        const grpc::Status status = render_once(channel_to(server->port()), request, &frame);
        EXPECT_EQ(status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << status.error_message();
        EXPECT_EQ(status.error_message(),
                  "max-session-memory: rendering scene 'city' needed 5760000 bytes of renderer memory; this server "
                  "allows 4000000 per session; lower the resolution");
        EXPECT_EQ(server->stats().pooled_renderers, 0);  // the oversized renderer was not kept
    }
    EXPECT_EQ(server->stats().out_of_memory, 2u);
    EXPECT_TRUE(eventually([&] { return server->stats().sessions_active == 0; }));
}

/// A client that stops reading: its frame sits in flow control; after stall_timeout_ms the
/// watchdog cancels the stream, within 10% of the timeout, and frees the session. The client
/// gets the reason although it reads nothing. Other streams are not touched.
TEST(ServerLimits, StallWatchdogCancelsAStreamWhoseClientStoppedReading) {
    constexpr int kTimeoutMs = 2000;
    server::ServerOptions o = test_options();
    o.limits.stall_timeout_ms = kTimeoutMs;
    auto server = start_server(o);
    BackgroundStream healthy(server->port());
    ASSERT_TRUE(healthy.advances(2));

    constexpr int kW = 320, kH = 180;  // raw frames of 172 KB fill the small windows at once
    grpc::ChannelArguments args = net::client_channel_args();
    args.SetInt(GRPC_ARG_HTTP2_BDP_PROBE, 0);
    args.SetInt(GRPC_ARG_HTTP2_STREAM_LOOKAHEAD_BYTES, 64 * 1024);
    StreamClient client(channel_to(server->port(), args));
    v1::SessionConfig config = session_config(v1::ENCODING_RAW_RGB8);
    config.set_width(kW);
    config.set_height(kH);
    config.mutable_pipeline()->set_cache(v1::CACHE_MODE_OFF);
    ASSERT_TRUE(client.open(config));
    const auto path = uav_path(20, kW, kH);
    const auto begin = std::chrono::steady_clock::now();
    std::uint64_t seq = 0;
    // Poses (acknowledging everything, reading nothing) until the server gives up on us.
    while (std::chrono::steady_clock::now() - begin < std::chrono::seconds(30)) {
        ++seq;
        if (!client.send(frame_request(seq, path[seq % path.size()], seq - 1))) break;
        if (server->stats().streams_stalled > 0) break;
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - begin).count();
    EXPECT_EQ(server->stats().streams_stalled, 1u);
    EXPECT_LT(seconds, 20.0);  // about 2-3 s: the windows fill within a few frames, then 2 s
    // The cancel carries the status past the unread frame, with how long that frame waited.
    const grpc::Status status = client.finish();
    std::printf("stall watchdog: cancelled after %.2f s (%llu poses sent); client status %d '%s'\n", seconds,
                static_cast<unsigned long long>(seq), static_cast<int>(status.error_code()),
                status.error_message().c_str());
    EXPECT_EQ(status.error_code(), grpc::StatusCode::DEADLINE_EXCEEDED) << status.error_message();
    long waited_ms = -1, limit_ms = -1;
    ASSERT_EQ(std::sscanf(status.error_message().c_str(),
                          "stall-timeout: the client took no frame off the wire for %ld ms (limit %ld ms)", &waited_ms,
                          &limit_ms),
              2)
        << status.error_message();
    EXPECT_EQ(limit_ms, kTimeoutMs);
    // The watchdog fires once the wait exceeds the limit; the message truncates it to whole
    // milliseconds, so 2000.4 ms reads 2000 (CI under ThreadSanitizer, 2026-12-02).
    EXPECT_GE(waited_ms, kTimeoutMs);
    EXPECT_LE(waited_ms, kTimeoutMs + kTimeoutMs / 10 * kTimingSlack) << "the watchdog fired more than 10% late";
    EXPECT_TRUE(eventually([&] { return server->stats().streams_open == 1; })) << server->stats().streams_open;
    EXPECT_TRUE(eventually([&] { return server->stats().sessions_active == 1; }));
    healthy.expect_kept_going();
    EXPECT_EQ(server->stats().streams_stalled, 1u);  // the healthy stream never stalled
}

/// A call that never sends its opening message is finished after open_timeout_ms with
/// DEADLINE_EXCEEDED naming the timeout, on time; one that opens in time is not touched.
/// Under ThreadSanitizer the server has read a message up to a second after it was written
/// (gRPC's own threads are not instrumented and run starved), so the timeout, and the margin
/// the late stream opens within, grow with the sanitizers' timing slack.
TEST(ServerLimits, AStreamWithoutItsOpeningMessageIsFinishedAfterTheOpenTimeout) {
    constexpr int kTimeoutMs = 1000 * kTimingSlack;
    server::ServerOptions o = test_options();
    o.limits.open_timeout_ms = kTimeoutMs;
    auto server = start_server(o);
    const auto begin = std::chrono::steady_clock::now();
    StreamClient silent(channel_to(server->port()));
    StreamClient late_but_in_time(channel_to(server->port()));
    std::this_thread::sleep_for(std::chrono::milliseconds(kTimeoutMs / 2));
    ASSERT_TRUE(late_but_in_time.open(session_config(v1::ENCODING_JPEG)));

    const grpc::Status status = silent.finish();
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - begin).count();
    EXPECT_EQ(status.error_code(), grpc::StatusCode::DEADLINE_EXCEEDED) << status.error_message();
    EXPECT_NE(status.error_message().find("open-timeout: no opening message (StreamRequest.open) within " +
                                          std::to_string(kTimeoutMs) + " ms"),
              std::string::npos)
        << status.error_message();
    EXPECT_GE(seconds, kTimeoutMs / 1000.0);
    // The watchdog's lateness (at most 10%), plus the round trip.
    EXPECT_LT(seconds, (kTimeoutMs + kTimeoutMs / 10 * kTimingSlack) / 1000.0 + 0.2 * kTimingSlack);
    EXPECT_EQ(server->stats().open_timeouts, 1u);

    // Long past the timeout, the opened stream still renders.
    std::this_thread::sleep_for(std::chrono::milliseconds(kTimeoutMs));
    ASSERT_TRUE(late_but_in_time.send(frame_request(1, uav_path(2)[0], 0)));
    v1::Frame frame;
    ASSERT_TRUE(late_but_in_time.stream->Read(&frame));
    EXPECT_FALSE(frame.has_error()) << frame.error().message();
    EXPECT_TRUE(late_but_in_time.close().ok());
    EXPECT_EQ(server->stats().open_timeouts, 1u);
}

/// Unary renders reuse pooled renderers (at most render_workers of them) and stay exact.
TEST(ServerLimits, UnaryRendersReuseRenderers) {
    auto server = start_server();
    auto stub = v1::RenderService::NewStub(channel_to(server->port()));
    const v1::RenderRequest request =
        render_request(session_config(v1::ENCODING_PNG), frame_request(1, uav_path(4)[1], 0));
    std::string first;
    for (int i = 0; i < 4; ++i) {
        grpc::ClientContext context;
        v1::Frame frame;
        const grpc::Status status = stub->Render(&context, request, &frame);
        ASSERT_TRUE(status.ok()) << status.error_message();
        if (i == 0) first = frame.data();
        EXPECT_EQ(frame.data(), first) << "render " << i << " differs";
        EXPECT_EQ(server->stats().pooled_renderers, 1);
    }
    // Concurrent calls take more renderers; the pool keeps at most render_workers (2).
    std::vector<std::thread> threads;
    std::atomic<int> ok{0};
    for (int t = 0; t < 6; ++t)
        threads.emplace_back([&] {
            grpc::ClientContext context;
            v1::Frame frame;
            if (stub->Render(&context, request, &frame).ok() && frame.data() == first) ++ok;
        });
    for (auto& t : threads) t.join();
    EXPECT_EQ(ok, 6);
    EXPECT_GE(server->stats().pooled_renderers, 1);
    EXPECT_LE(server->stats().pooled_renderers, 2);
}

/// A closed stream's renderer waits in the pool, keeping its scene on the device (no second
/// upload); the next session takes it, its cache reset, and draws the same frame.
TEST(ServerLimits, StreamSessionsReuseRenderers) {
    auto device = std::make_shared<FakeDevice>(1'000'000'000, 0);
    server::ServerOptions o = test_options();
    o.renderer_factory = device->factory();
    auto server = start_server(o);
    const v1::FrameRequest pose = frame_request(1, uav_path(4)[2], 0);
    std::string first;
    for (int session = 0; session < 3; ++session) {
        StreamClient client(channel_to(server->port()));
        ASSERT_TRUE(client.open(session_config(v1::ENCODING_PNG)));
        ASSERT_TRUE(client.send(pose));
        v1::Frame frame;
        ASSERT_TRUE(client.stream->Read(&frame));
        ASSERT_FALSE(frame.has_error()) << frame.error().message();
        if (session == 0) first = frame.data();
        EXPECT_EQ(frame.data(), first) << "session " << session;
        EXPECT_EQ(server->stats().pooled_renderers, 0) << "the open session holds the renderer";
        const std::uint64_t scene_bytes = device->used();
        EXPECT_GT(scene_bytes, 0u);
        EXPECT_TRUE(client.close().ok());
        ASSERT_TRUE(eventually([&] { return server->stats().pooled_renderers == 1; })) << "session " << session;
        EXPECT_EQ(device->used(), scene_bytes) << "the pooled renderer keeps the one copy of the scene";
    }
}

/// Start-up scenes are on every device before their first session (ServerOptions::prewarm): an
/// idle renderer on each holds each scene; the first session takes one and uploads nothing.
TEST(ServerLimits, StartUpScenesAreResidentBeforeTheFirstSession) {
    auto device = std::make_shared<FakeDevice>(1'000'000'000, 0);
    server::ServerOptions o = test_options();
    o.renderer_factory = device->factory();
    o.devices = {0, 1};
    o.render_workers = 4;  // the pool keeps at most 4 idle renderers: two scenes on two devices
    o.preload.push_back("small=builtin:city?gaussians=10000&seed=3");
    o.prewarm = true;
    auto server = start_server(o);
    for (const std::string scene : {"city", "small"}) {
        const std::vector<server::DevicePlacement::SceneOnDevice> resident =
            server->core().placement().residency(scene);
        ASSERT_EQ(resident.size(), 2u) << scene;
        for (const auto& d : resident) {
            EXPECT_EQ(d.pooled_renderers, 1) << scene << " on device " << d.device;
            EXPECT_EQ(d.sessions, 0) << scene << " on device " << d.device;
        }
    }
    const std::uint64_t scene_bytes = device->used();
    EXPECT_GT(scene_bytes, 0u);
    StreamClient client(channel_to(server->port()));
    ASSERT_TRUE(client.open(session_config(v1::ENCODING_JPEG)));
    ASSERT_TRUE(client.send(frame_request(1, uav_path(2)[0], 0)));
    v1::Frame frame;
    ASSERT_TRUE(client.stream->Read(&frame));
    EXPECT_FALSE(frame.has_error()) << frame.error().message();
    EXPECT_EQ(server->stats().pooled_renderers, 3) << "the session took one of the four";
    EXPECT_EQ(device->used(), scene_bytes) << "nothing uploaded again";
    EXPECT_TRUE(client.close().ok());
    EXPECT_TRUE(eventually([&] { return server->stats().pooled_renderers == 4; }));
}

/// A flood of stream calls that never open is bounded: past max_streams() calls alive, a new
/// call ends at once with RESOURCE_EXHAUSTED naming the limit; once the idle calls end, a
/// stream opens and renders again.
TEST(ServerLimits, StreamCallsBeyondTheLimitAreRefusedByName) {
    auto server = start_server();
    const int limit = server::kStreamsAwaitingAdmission + test_options().limits.max_sessions;  // one device
    auto channel = channel_to(server->port());
    std::vector<std::unique_ptr<StreamClient>> idle;
    for (int i = 0; i < limit; ++i) idle.push_back(std::make_unique<StreamClient>(channel));
    ASSERT_TRUE(eventually([&] { return server->stats().streams_open == limit; }, std::chrono::seconds(30)))
        << server->stats().streams_open;

    StreamClient refused(channel);
    const grpc::Status status = refused.finish();
    EXPECT_EQ(status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << status.error_message();
    EXPECT_EQ(status.error_message(), "max-streams: " + std::to_string(limit) +
                                          " stream calls are open, the most this server takes (" +
                                          std::to_string(limit) + "); finish idle ones or retry later");
    EXPECT_EQ(server->stats().streams_refused, 1u);

    for (auto& call : idle) call->context.TryCancel();
    idle.clear();
    ASSERT_TRUE(eventually([&] { return server->stats().streams_open == 0; }, std::chrono::seconds(30)));
    StreamClient client(channel);
    ASSERT_TRUE(client.open(session_config(v1::ENCODING_JPEG)));
    ASSERT_TRUE(client.send(frame_request(1, uav_path(2)[0], 0)));
    v1::Frame frame;
    ASSERT_TRUE(client.stream->Read(&frame));
    EXPECT_FALSE(frame.has_error()) << frame.error().message();
    EXPECT_TRUE(client.close().ok());
}

}  // namespace
}  // namespace catgs::test
