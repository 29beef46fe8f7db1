// Backpressure: latest pose wins, at most max_unacked_frames unacknowledged frames, bounded
// server memory with clients that stop reading or vanish, and other streams unaffected.
#include "server_test_util.hpp"

namespace catgs::test {
namespace {

class FlowControlTest : public HealthyStreamTest<FlowControlTest> {
public:
    static server::ServerOptions options() {
        server::ServerOptions o = test_options();
        o.limits.max_width = 640;
        o.limits.max_height = 360;
        return o;
    }

protected:
    void TearDown() override {
        HealthyStreamTest::TearDown();
        // Every stream of the test is gone, with its admission slot and scene lease.
        EXPECT_TRUE(eventually([] { return server_->stats().streams_open == 0; })) << server_->stats().streams_open;
        EXPECT_TRUE(eventually([] { return server_->stats().sessions_active == 0; }));
        server::SceneSummary city;
        ASSERT_TRUE(server_->core().scenes().get("city", &city).ok());
        EXPECT_TRUE(eventually([&] {
            server_->core().scenes().get("city", &city);
            return city.sessions == 0;
        })) << city.sessions;
        EXPECT_EQ(server_->stats().frames_buffered, 0);
    }
};

/// A client that neither reads nor acknowledges gets max_unacked_frames frames; every other
/// pose is coalesced, and the newest one is what renders when it finally closes.
TEST_F(FlowControlTest, LatestPoseWinsWhenTheClientDoesNotAcknowledge) {
    constexpr int kPoses = 40;
    const auto path = uav_path(kPoses);
    StreamClient client(channel_to(server_->port()));
    v1::SessionConfig config = session_config(v1::ENCODING_JPEG);
    config.set_max_unacked_frames(2);
    ASSERT_TRUE(client.open(config));
    // The first two poses each render: the client waits to receive each frame (receiving is
    // not acknowledging) before it sends the next pose. Fixed sleeps here were a flake: under
    // TSan on two busy cores the session was still opening when pose 2 came, and coalesced
    // pose 1.
    std::vector<v1::Frame> frames(2);
    ASSERT_TRUE(client.send(frame_request(1, path[0], 0)));
    ASSERT_TRUE(client.stream->Read(&frames[0]));
    ASSERT_TRUE(client.send(frame_request(2, path[1], 0)));
    ASSERT_TRUE(client.stream->Read(&frames[1]));
    // ...then the credit is spent: the rest must wait, and only the newest survives.
    const auto coalesced_before = server_->stats().poses_coalesced;
    for (int i = 2; i < kPoses; ++i)
        ASSERT_TRUE(client.send(frame_request(static_cast<std::uint64_t>(i + 1), path[i], 0)));
    ASSERT_TRUE(eventually([&] { return server_->stats().poses_coalesced - coalesced_before >= kPoses - 3; }));
    // Give the server time to (wrongly) render more than its credit.
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    client.stream->WritesDone();
    for (v1::Frame f; client.stream->Read(&f);) frames.push_back(f);
    ASSERT_TRUE(client.stream->Finish().ok());
    // Two within the credit, and the newest pose, rendered after the client half-closed.
    ASSERT_EQ(frames.size(), 3u);
    EXPECT_EQ(frames[0].sequence(), 1u);
    EXPECT_EQ(frames[1].sequence(), 2u);
    EXPECT_EQ(frames[2].sequence(), static_cast<std::uint64_t>(kPoses));
    EXPECT_EQ(frames[2].stats().requests_received(), static_cast<std::uint64_t>(kPoses));
    EXPECT_EQ(frames[2].stats().poses_coalesced(), static_cast<std::uint64_t>(kPoses - 3));
    for (const auto& f : frames) EXPECT_FALSE(f.has_error()) << f.error().message();
}

/// Acknowledging frees credit: a client that acknowledges each frame keeps getting them.
TEST_F(FlowControlTest, AcknowledgementsFreeCredit) {
    const auto path = uav_path(10);
    StreamClient client(channel_to(server_->port()));
    v1::SessionConfig config = session_config(v1::ENCODING_JPEG);
    config.set_max_unacked_frames(1);
    ASSERT_TRUE(client.open(config));
    std::uint64_t ack = 0;
    for (int i = 0; i < 10; ++i) {
        ASSERT_TRUE(client.send(frame_request(static_cast<std::uint64_t>(i + 1), path[i], ack)));
        v1::Frame f;
        ASSERT_TRUE(client.stream->Read(&f));
        EXPECT_EQ(f.sequence(), static_cast<std::uint64_t>(i + 1));
        ack = f.sequence();
    }
    EXPECT_TRUE(client.close().ok());
}

/// A client that claims to have received everything but never reads: the transport backs up,
/// the server coalesces frames instead of queueing them, and its memory stays bounded.
TEST_F(FlowControlTest, ClientThatNeverReadsKeepsServerMemoryBounded) {
    constexpr int kW = 320, kH = 180;  // raw frames of 172 KB fill the transport windows fast
    grpc::ChannelArguments args = net::client_channel_args();
    // Small client windows, so that the transport cannot absorb the frames (see ecosystem.md).
    args.SetInt(GRPC_ARG_HTTP2_BDP_PROBE, 0);
    args.SetInt(GRPC_ARG_HTTP2_STREAM_LOOKAHEAD_BYTES, 64 * 1024);
    StreamClient client(channel_to(server_->port(), args));
    v1::SessionConfig config = session_config(v1::ENCODING_RAW_RGB8);
    config.set_width(kW);
    config.set_height(kH);
    config.mutable_pipeline()->set_cache(v1::CACHE_MODE_OFF);
    ASSERT_TRUE(client.open(config));
    const auto path = uav_path(50, kW, kH);
    const auto before = server_->stats();
    const long rss_before = rss_kb();
    std::uint64_t seq = 0;
    const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(4);
    std::int64_t max_buffered_bytes = 0;
    while (std::chrono::steady_clock::now() < end) {
        ++seq;
        // Lies: acknowledges every frame so far without reading any.
        ASSERT_TRUE(client.send(frame_request(seq, path[seq % path.size()], seq - 1)));
        max_buffered_bytes = std::max(max_buffered_bytes, server_->stats().bytes_buffered);
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    const auto after = server_->stats();
    const long rss_after = rss_kb();
    std::printf(
        "never-reads: %llu poses sent; server sent %llu frames, coalesced %llu poses and %llu frames; "
        "peak %lld frames per session, %lld bytes buffered; RSS +%ld kB\n",
        static_cast<unsigned long long>(seq), static_cast<unsigned long long>(after.frames_sent - before.frames_sent),
        static_cast<unsigned long long>(after.poses_coalesced - before.poses_coalesced),
        static_cast<unsigned long long>(after.frames_coalesced - before.frames_coalesced),
        static_cast<long long>(after.peak_session_buffered), static_cast<long long>(max_buffered_bytes),
        rss_after - rss_before);
    // One frame in gRPC's hands plus one waiting, per session, never more.
    EXPECT_LE(after.peak_session_buffered, 2);
    // Two sessions (this and the healthy one), at most two frames each.
    EXPECT_LE(max_buffered_bytes, 4 * 3 * kW * kH);
    // The server had to drop work for this client: it stopped taking frames. It dropped poses,
    // never rendered frames: a render starts only when its frame will be written.
    EXPECT_GT(after.poses_coalesced - before.poses_coalesced, 0u);
    EXPECT_EQ(after.frames_coalesced - before.frames_coalesced, 0u);
    // The process (server and test) did not grow with the frames it could not send.
    EXPECT_LT(rss_after - rss_before, 64 * 1024);
    client.context.TryCancel();
    EXPECT_EQ(client.finish().error_code(), grpc::StatusCode::CANCELLED);
}

/// A client that vanishes mid-stream (cancel) frees its session; the others continue.
TEST_F(FlowControlTest, ClientDisconnectingMidStreamFreesItsSession) {
    const auto path = uav_path(20);
    for (int round = 0; round < 3; ++round) {
        auto client = std::make_unique<StreamClient>(channel_to(server_->port()));
        ASSERT_TRUE(client->open(session_config(v1::ENCODING_PNG)));
        std::uint64_t ack = 0;
        for (int i = 0; i < 3; ++i) {
            ASSERT_TRUE(client->send(frame_request(static_cast<std::uint64_t>(i + 1), path[i], ack)));
            v1::Frame f;
            ASSERT_TRUE(client->stream->Read(&f));
            ack = f.sequence();
        }
        // Poses in flight and a render possibly running when it goes.
        client->send(frame_request(4, path[4], ack));
        client->send(frame_request(5, path[5], ack));
        client->context.TryCancel();
        client.reset();
        EXPECT_TRUE(eventually([] { return server_->stats().streams_open == 1; })) << server_->stats().streams_open;
    }
}

/// Half-closing right after a pose still delivers that pose's frame, then OK.
TEST_F(FlowControlTest, HalfCloseDeliversThePendingFrame) {
    const auto path = uav_path(3);
    StreamClient client(channel_to(server_->port()));
    ASSERT_TRUE(client.open(session_config(v1::ENCODING_PNG)));
    ASSERT_TRUE(client.send(frame_request(1, path[1], 0)));
    client.stream->WritesDone();
    v1::Frame f;
    ASSERT_TRUE(client.stream->Read(&f));
    EXPECT_EQ(f.sequence(), 1u);
    EXPECT_FALSE(client.stream->Read(&f));
    EXPECT_TRUE(client.stream->Finish().ok());
}

}  // namespace
}  // namespace catgs::test
