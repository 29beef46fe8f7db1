// Graceful drain of the catgs-server binary on SIGTERM, step by step, as Kubernetes expects
// (docs/server.md, "Shutdown"): health NOT_SERVING at once on both listeners, the listeners
// open for --drain-ms with new sessions refused, every running stream ended with the shutdown
// message (a client that does not read included), and exit status 0 after the drain.
#include <cstdio>

#include "process_util.hpp"
#include "server_test_util.hpp"

namespace catgs::test {
namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t) {
    return std::chrono::duration<double>(Clock::now() - t).count();
}

/// The health listener's port, from the server's start-up log line.
int health_port_of(const Child& server) {
    if (!server.wait_for_output(", health on port ", std::chrono::seconds(30))) return 0;
    const std::string out = server.output();
    int port = 0;
    std::sscanf(out.c_str() + out.find(", health on port "), ", health on port %d", &port);
    return port;
}

bool is_shutdown_message(const grpc::Status& status) {
    return status.error_code() == grpc::StatusCode::UNAVAILABLE &&
           status.error_message().find("server is shutting down: reconnect") != std::string::npos;
}

TEST(ServerDrain, SigtermDrainsAsKubernetesExpects) {
    constexpr int kDrainMs = 3000 * kTimingSlack, kGraceMs = 2000 * kTimingSlack;
    Child server({CATGS_SERVER_BINARY, "--address", "127.0.0.1:0", "--health-address", "127.0.0.1:0", "--backend",
                  "cpu", "--scene", "city=builtin:city?gaussians=10000&seed=1", "--render-threads", "1", "--drain-ms",
                  std::to_string(kDrainMs), "--shutdown-grace-ms", std::to_string(kGraceMs)});
    const int port = wait_for_port(server);
    ASSERT_GT(port, 0) << server.output();
    const int health_port = health_port_of(server);
    ASSERT_GT(health_port, 0) << server.output();
    ASSERT_EQ(health(port, ""), HealthStatus::SERVING);
    ASSERT_EQ(health(health_port, "catgs.v1.RenderService"), HealthStatus::SERVING);

    // Session 1: a viewer that reads its frames.
    const auto path = uav_path(20, 320, 180);
    auto reading = std::make_unique<StreamClient>(channel_to(port));
    ASSERT_TRUE(reading->open(session_config(v1::ENCODING_JPEG)));
    ASSERT_TRUE(reading->send(frame_request(1, path[0], 0)));
    v1::Frame frame;
    ASSERT_TRUE(reading->stream->Read(&frame));
    ASSERT_FALSE(frame.has_error()) << frame.error().message();

    // Session 2: a viewer that acknowledges everything and reads nothing, on its own
    // connection with small windows: raw frames of 172 KB leave a write stuck in flow control.
    grpc::ChannelArguments args = net::client_channel_args();
    args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
    args.SetInt(GRPC_ARG_HTTP2_BDP_PROBE, 0);
    args.SetInt(GRPC_ARG_HTTP2_STREAM_LOOKAHEAD_BYTES, 64 * 1024);
    auto stuck = std::make_unique<StreamClient>(channel_to(port, args));
    v1::SessionConfig config = session_config(v1::ENCODING_RAW_RGB8);
    config.set_width(320);
    config.set_height(180);
    config.mutable_pipeline()->set_cache(v1::CACHE_MODE_OFF);
    ASSERT_TRUE(stuck->open(config));
    for (std::uint64_t seq = 1; seq <= 40; ++seq) {
        ASSERT_TRUE(stuck->send(frame_request(seq, path[seq % path.size()], seq - 1)));
        std::this_thread::sleep_for(std::chrono::milliseconds(25));
    }

    const auto sigterm = Clock::now();
    server.kill(SIGTERM);

    // 1. Health turns NOT_SERVING at once on both listeners, which still answer.
    grpc::Status main_call, health_call;
    EXPECT_TRUE(eventually([&] { return health(port, "", &main_call) == HealthStatus::NOT_SERVING; },
                           std::chrono::milliseconds(1000 * kTimingSlack)))
        << main_call.error_message();
    EXPECT_TRUE(eventually(
        [&] { return health(health_port, "catgs.v1.RenderService", &health_call) == HealthStatus::NOT_SERVING; },
        std::chrono::milliseconds(1000 * kTimingSlack)))
        << health_call.error_message();
    EXPECT_LT(seconds_since(sigterm), 1.0 * kTimingSlack);

    // 2. The reading stream ends with the shutdown message, without waiting for the drain.
    const grpc::Status reading_status = reading->finish();
    EXPECT_TRUE(is_shutdown_message(reading_status))
        << reading_status.error_code() << " " << reading_status.error_message();
    EXPECT_LT(seconds_since(sigterm), 1.5 * kTimingSlack);
    // Each client closes its connection when done: an idle synchronous client has no thread
    // reading its socket, so it would see gRPC's GOAWAY late and hold the server's exit.
    reading.reset();

    // 3. The stream that never read is cancelled with the shutdown status, not gRPC's
    //    "Cancelling all calls" at the end: its session has ended on the server before the
    //    client reads anything, so what the client reads now was decided without its reading.
    EXPECT_TRUE(server.wait_for_output("cancelling 1 stream(s) whose client does not read", std::chrono::seconds(2)))
        << server.output();
    EXPECT_TRUE(
        server.wait_for_output("session 2 closed: 14 'server is shutting down: reconnect", std::chrono::seconds(2)))
        << server.output();
    const grpc::Status stuck_status = stuck->finish();
    EXPECT_TRUE(is_shutdown_message(stuck_status)) << stuck_status.error_code() << " " << stuck_status.error_message();
    EXPECT_EQ(stuck_status.error_message().find("Cancelling all calls"), std::string::npos);
    stuck.reset();

    // 4. Well into the drain the listeners are still open: health answers NOT_SERVING, and new
    //    streams and unary renders are refused with the shutdown message.
    std::this_thread::sleep_until(sigterm + std::chrono::milliseconds(kDrainMs * 2 / 3));
    EXPECT_EQ(health(port, "", &main_call), HealthStatus::NOT_SERVING) << main_call.error_message();
    EXPECT_EQ(health(health_port, "", &health_call), HealthStatus::NOT_SERVING) << health_call.error_message();
    {
        StreamClient late(channel_to(port));
        late.open(session_config(v1::ENCODING_JPEG));
        const grpc::Status late_status = late.close();
        EXPECT_TRUE(is_shutdown_message(late_status)) << late_status.error_code() << " " << late_status.error_message();
    }
    v1::Frame unary;
    const grpc::Status unary_status = render_once(
        channel_to(port), render_request(session_config(v1::ENCODING_PNG), frame_request(1, path[1], 0)), &unary);
    EXPECT_TRUE(is_shutdown_message(unary_status)) << unary_status.error_code() << " " << unary_status.error_message();
    EXPECT_LT(seconds_since(sigterm), kDrainMs / 1000.0) << "the checks above ran past the drain";

    // 5. After the drain the server exits 0, without using the grace period (no call is left).
    const std::optional<int> code = server.wait(std::chrono::milliseconds(kDrainMs + kGraceMs + 5000));
    const double exited = seconds_since(sigterm);
    ASSERT_TRUE(code.has_value()) << "still running after the drain and the grace period\n" << server.output();
    EXPECT_EQ(*code, 0) << server.output();
    EXPECT_GE(exited, kDrainMs / 1000.0);
    EXPECT_LT(exited, (kDrainMs + kGraceMs) / 1000.0) << server.output();
    // And the listeners are closed.
    EXPECT_EQ(health(health_port, "", &health_call), HealthStatus::UNKNOWN);
    EXPECT_EQ(health_call.error_code(), grpc::StatusCode::UNAVAILABLE) << health_call.error_message();
}

/// --drain-ms 0: no drain period; SIGTERM still ends every stream with the shutdown message
/// and exits 0 at once.
TEST(ServerDrain, ZeroDrainStopsAtOnce) {
    Child server({CATGS_SERVER_BINARY, "--address", "127.0.0.1:0", "--backend", "cpu", "--scene",
                  "city=builtin:city?gaussians=10000&seed=1", "--render-threads", "1", "--drain-ms", "0"});
    const int port = wait_for_port(server);
    ASSERT_GT(port, 0) << server.output();
    const auto sigterm = [&] {
        StreamClient reading(channel_to(port));
        EXPECT_TRUE(reading.open(session_config(v1::ENCODING_JPEG)));
        EXPECT_TRUE(reading.send(frame_request(1, uav_path(2)[0], 0)));
        v1::Frame frame;
        EXPECT_TRUE(reading.stream->Read(&frame));
        const auto t = Clock::now();
        server.kill(SIGTERM);
        const grpc::Status status = reading.finish();
        EXPECT_TRUE(is_shutdown_message(status)) << status.error_code() << " " << status.error_message();
        return t;
    }();
    EXPECT_EQ(server.wait(std::chrono::seconds(10)).value_or(-1), 0) << server.output();
    EXPECT_LT(seconds_since(sigterm), 2.0 * kTimingSlack) << server.output();
}

TEST(ServerDrain, NegativeDrainIsABadFlag) {
    Child server({CATGS_SERVER_BINARY, "--address", "127.0.0.1:0", "--backend", "cpu", "--drain-ms", "-1"});
    EXPECT_EQ(server.wait(std::chrono::seconds(20)).value_or(-1), 2) << server.output();
    EXPECT_NE(server.output().find("--drain-ms/--shutdown-grace-ms must be >= 0"), std::string::npos)
        << server.output();
}

}  // namespace
}  // namespace catgs::test
