// The one fixture of the server integration tests: an in-process server on 127.0.0.1:0 with a
// small built-in city (per test, or shared by a suite: SharedServerTest), stream clients, a
// healthy background stream, unary and SceneService calls, image decoders and the reference
// renderer.
#pragma once

#include <gtest/gtest.h>
#include <grpcpp/grpcpp.h>
#include <png.h>
#include <turbojpeg.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "catgs/common/pose_wire.hpp"
#include "catgs/image.hpp"
#include "catgs/renderer.hpp"
#include "catgs/scene_io.hpp"
#include "catgs/common/net_config.hpp"
#include "catgs/server/request_validation.hpp"
#include "catgs/server/server.hpp"
#include "catgs/trajectory.hpp"
#include "catgs/v1/catgs.grpc.pb.h"
#include "grpc/health/v1/health.grpc.pb.h"

namespace catgs::test {

inline constexpr const char* kTestScene = "builtin:city?gaussians=20000&seed=1";
/// How much the timing bounds of the tests stretch: 1, or more under sanitizers.
inline constexpr int kTimingSlack = CATGS_TIMING_SLACK;
inline constexpr int kWidth = 160, kHeight = 90;

inline server::ServerOptions test_options() {
    server::ServerOptions o;
    o.address = "127.0.0.1:0";
    o.preload = {std::string("city=") + kTestScene};
    o.backend = "cpu";
    o.render_threads = 2;
    o.render_workers = 2;
    o.prewarm = false;  // the tests count pooled renderers and device memory from zero
    o.encode_workers = 2;
    o.shutdown_grace_ms = 2000;
    return o;
}

inline std::unique_ptr<server::Server> start_server(server::ServerOptions options = test_options()) {
    auto s = std::make_unique<server::Server>(std::move(options));
    s->start();
    return s;
}

inline std::shared_ptr<grpc::Channel> channel_to(int port, grpc::ChannelArguments args = net::client_channel_args()) {
    return grpc::CreateCustomChannel("127.0.0.1:" + std::to_string(port), grpc::InsecureChannelCredentials(), args);
}

/// Polls `condition` for up to `timeout`.
template <typename F>
bool eventually(F condition, std::chrono::milliseconds timeout = std::chrono::milliseconds(10000)) {
    const auto end = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < end) {
        if (condition()) return true;
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return condition();
}

inline v1::SessionConfig session_config(v1::Encoding encoding, int quality = 0, const std::string& scene = "city") {
    v1::SessionConfig c;
    c.set_scene_id(scene);
    c.set_width(kWidth);
    c.set_height(kHeight);
    c.set_horizontal_fov_degrees(70);
    c.mutable_encoding()->set_encoding(encoding);
    c.mutable_encoding()->set_jpeg_quality(quality);
    return c;
}

inline v1::Pose pose_of(const Camera& camera) {
    return wire::to_proto(camera.pose);
}

/// The shared test scene (generated once per process).
inline std::shared_ptr<const Scene> test_scene() {
    static std::shared_ptr<const Scene> scene = std::make_shared<const Scene>(load_scene(kTestScene));
    return scene;
}

/// A UAV path over the test scene.
inline std::vector<Camera> uav_path(int frames, int width = kWidth, int height = kHeight) {
    return make_trajectory("builtin:flythrough?frames=" + std::to_string(frames) + "&altitude=40&speed=6",
                           test_scene()->bounds, intrinsics_from_fov(width, height, 70));
}

inline v1::FrameRequest frame_request(std::uint64_t sequence, const Camera& camera, std::uint64_t ack) {
    v1::FrameRequest r;
    r.set_sequence(sequence);
    *r.mutable_pose() = pose_of(camera);
    r.set_client_timestamp_us(static_cast<std::int64_t>(sequence) * 33'333);
    r.set_last_received_sequence(ack);
    return r;
}

inline v1::StreamRequest open_message(const v1::SessionConfig& config) {
    v1::StreamRequest r;
    *r.mutable_open() = config;
    return r;
}

inline v1::StreamRequest frame_message(const v1::FrameRequest& frame) {
    v1::StreamRequest r;
    *r.mutable_frame() = frame;
    return r;
}

using HealthStatus = grpc::health::v1::HealthCheckResponse;

/// grpc.health.v1.Health/Check of `service` ("" = the whole server) over `channel`, with a
/// 5 s deadline; UNKNOWN when the call fails, its status in *status.
inline HealthStatus::ServingStatus health(const std::shared_ptr<grpc::Channel>& channel, const std::string& service,
                                          grpc::Status* status = nullptr) {
    auto stub = grpc::health::v1::Health::NewStub(channel);
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(5));
    grpc::health::v1::HealthCheckRequest request;
    request.set_service(service);
    HealthStatus response;
    grpc::Status s = stub->Check(&context, request, &response);
    if (status) *status = s;
    return s.ok() ? response.status() : HealthStatus::UNKNOWN;
}

/// The same over a plaintext channel to `port`.
inline HealthStatus::ServingStatus health(int port, const std::string& service, grpc::Status* status = nullptr) {
    return health(channel_to(port), service, status);
}

/// The whole server reports SERVING on `port`.
inline bool serving(int port) {
    return health(port, "") == HealthStatus::SERVING;
}

/// A unary RenderService.Render request.
inline v1::RenderRequest render_request(const v1::SessionConfig& config, const v1::FrameRequest& frame) {
    v1::RenderRequest r;
    *r.mutable_config() = config;
    *r.mutable_frame() = frame;
    return r;
}

/// RenderService.Render over `channel`; the frame in *frame.
inline grpc::Status render_once(const std::shared_ptr<grpc::Channel>& channel, const v1::RenderRequest& request,
                                v1::Frame* frame) {
    auto stub = v1::RenderService::NewStub(channel);
    grpc::ClientContext context;
    return stub->Render(&context, request, frame);
}

/// SceneService.LoadScene of `source` as `id` ("": the server derives it); the scene in *info.
inline grpc::Status load_scene_call(v1::SceneService::Stub& stub, const std::string& source, const std::string& id,
                                    v1::SceneInfo* info = nullptr) {
    grpc::ClientContext context;
    v1::LoadSceneRequest request;
    request.set_source(source);
    request.set_scene_id(id);
    v1::SceneInfo ignored;
    return stub.LoadScene(&context, request, info ? info : &ignored);
}

/// A synchronous stream: open it, then send/receive.
struct StreamClient {
    grpc::ClientContext context;
    std::unique_ptr<v1::RenderService::Stub> stub;
    std::unique_ptr<grpc::ClientReaderWriter<v1::StreamRequest, v1::Frame>> stream;

    explicit StreamClient(const std::shared_ptr<grpc::Channel>& channel, const std::string& authorization = "",
                          std::chrono::seconds deadline = std::chrono::seconds(60))
        : stub(v1::RenderService::NewStub(channel)) {
        if (!authorization.empty()) context.AddMetadata("authorization", authorization);
        context.set_deadline(std::chrono::system_clock::now() + deadline);
        stream = stub->Stream(&context);
    }
    bool open(const v1::SessionConfig& config) { return stream->Write(open_message(config)); }
    bool send(const v1::FrameRequest& frame) { return stream->Write(frame_message(frame)); }
    grpc::Status close() {
        stream->WritesDone();
        v1::Frame ignored;
        while (stream->Read(&ignored)) {
        }
        return stream->Finish();
    }
    /// Reads until the stream ends; returns its status.
    grpc::Status finish() {
        v1::Frame ignored;
        while (stream->Read(&ignored)) {
        }
        return stream->Finish();
    }
};

/// A new stream with `config` gets a frame for its first pose, and closes OK.
inline void expect_one_frame(const std::shared_ptr<grpc::Channel>& channel,
                             const v1::SessionConfig& config = session_config(v1::ENCODING_JPEG)) {
    StreamClient client(channel);
    ASSERT_TRUE(client.open(config));
    ASSERT_TRUE(client.send(frame_request(1, uav_path(2)[0], 0)));
    v1::Frame frame;
    ASSERT_TRUE(client.stream->Read(&frame));
    EXPECT_FALSE(frame.has_error()) << frame.error().message();
    EXPECT_FALSE(frame.data().empty());
    EXPECT_TRUE(client.close().ok());
}

inline ImageRGB8 decode_png(const std::string& data) {
    png_image image{};
    image.version = PNG_IMAGE_VERSION;
    EXPECT_NE(png_image_begin_read_from_memory(&image, data.data(), data.size()), 0) << image.message;
    image.format = PNG_FORMAT_RGB;
    ImageRGB8 out;
    out.width = static_cast<int>(image.width);
    out.height = static_cast<int>(image.height);
    out.rgb.resize(PNG_IMAGE_SIZE(image));
    EXPECT_NE(png_image_finish_read(&image, nullptr, out.rgb.data(), 0, nullptr), 0) << image.message;
    return out;
}

inline ImageRGB8 decode_jpeg(const std::string& data) {
    tjhandle handle = tjInitDecompress();
    int width = 0, height = 0, subsampling = 0, colorspace = 0;
    auto* bytes = reinterpret_cast<const unsigned char*>(data.data());
    EXPECT_EQ(tjDecompressHeader3(handle, bytes, data.size(), &width, &height, &subsampling, &colorspace), 0);
    ImageRGB8 out;
    out.width = width;
    out.height = height;
    out.rgb.resize(3 * static_cast<std::size_t>(width) * static_cast<std::size_t>(height));
    EXPECT_EQ(tjDecompress2(handle, bytes, data.size(), out.rgb.data(), width, 0, height, TJPF_RGB, 0), 0);
    tjDestroy(handle);
    return out;
}

inline ImageRGB8 decode_frame(const v1::Frame& frame) {
    switch (frame.encoding()) {
        case v1::ENCODING_PNG:
            return decode_png(frame.data());
        case v1::ENCODING_JPEG:
            return decode_jpeg(frame.data());
        default: {
            ImageRGB8 out;
            out.width = static_cast<int>(frame.width());
            out.height = static_cast<int>(frame.height());
            out.rgb.assign(frame.data().begin(), frame.data().end());
            return out;
        }
    }
}

/// Current resident set size of this process (kB), from /proc/self/status.
inline long rss_kb() {
    std::ifstream in("/proc/self/status");
    std::string line;
    while (std::getline(in, line))
        if (line.rfind("VmRSS:", 0) == 0) return std::stol(line.substr(6));
    return -1;
}

/// A healthy stream that keeps rendering in lock step on its own thread while a test does
/// something nasty; `frames` counts what it received.
class BackgroundStream {
public:
    explicit BackgroundStream(int port) : channel_(channel_to(port)), client_(channel_) {
        thread_ = std::thread([this] { run(); });
    }
    ~BackgroundStream() { stop(); }
    void stop() {
        stop_ = true;
        if (thread_.joinable()) thread_.join();
    }
    int frames() const { return frames_; }
    bool failed() const { return failed_; }
    std::string failure() const { return failure_; }
    /// At the end of a test: the stream kept receiving frames, without an error; stops it.
    void expect_kept_going() {
        EXPECT_TRUE(advances(3)) << "the healthy stream stalled";
        stop();
        EXPECT_FALSE(failed()) << failure();
    }
    /// Waits until at least `more` further frames arrived.
    bool advances(int more, std::chrono::milliseconds timeout = std::chrono::milliseconds(20000)) {
        const int start = frames_;
        return eventually([&] { return frames_ >= start + more; }, timeout);
    }

private:
    void run() {
        const auto path = uav_path(60);
        if (!client_.open(session_config(v1::ENCODING_JPEG, 80))) {
            failed_ = true;
            failure_ = "open failed";
            return;
        }
        std::uint64_t seq = 0, ack = 0;
        while (!stop_) {
            ++seq;
            if (!client_.send(frame_request(seq, path[seq % path.size()], ack))) break;
            v1::Frame frame;
            if (!client_.stream->Read(&frame)) break;
            if (frame.has_error()) {
                failed_ = true;
                failure_ = frame.error().message();
            }
            ack = frame.sequence();
            ++frames_;
        }
        client_.stream->WritesDone();
        v1::Frame rest;
        while (client_.stream->Read(&rest)) {
        }
        grpc::Status s = client_.stream->Finish();
        if (!stop_ || !s.ok()) {
            failed_ = true;
            failure_ = "stream ended early: " + s.error_message();
        }
    }
    std::shared_ptr<grpc::Channel> channel_;
    StreamClient client_;
    std::thread thread_;
    std::atomic<bool> stop_{false}, failed_{false};
    std::atomic<int> frames_{0};
    std::string failure_;
};

/// One server for all the tests of a suite. `Suite`, the fixture deriving from this, may
/// define `static server::ServerOptions options()` to start it differently.
template <typename Suite>
class SharedServerTest : public ::testing::Test {
protected:
    static server::ServerOptions options() { return test_options(); }
    static void SetUpTestSuite() { server_ = start_server(Suite::options()).release(); }
    static void TearDownTestSuite() {
        delete server_;
        server_ = nullptr;
    }
    static inline server::Server* server_ = nullptr;
};

/// SharedServerTest, with a healthy stream running through each test: it must keep receiving
/// frames whatever the test does to the server.
template <typename Suite>
class HealthyStreamTest : public SharedServerTest<Suite> {
protected:
    void SetUp() override {
        healthy_ = std::make_unique<BackgroundStream>(this->server_->port());
        ASSERT_TRUE(healthy_->advances(2)) << "the healthy stream does not run";
    }
    void TearDown() override { healthy_->expect_kept_going(); }
    std::unique_ptr<BackgroundStream> healthy_;
};

/// A server per test whose scene root is a fresh directory of this process (ctest runs a
/// suite's tests in parallel processes), removed afterwards; SceneService calls on it.
class SceneRootTest : public ::testing::Test {
protected:
    /// Makes base_ (CATGS_TEST_TMP/<name>-<pid>, emptied) and the empty root_ in it.
    void make_root(const std::string& name) {
        base_ = std::filesystem::path(CATGS_TEST_TMP) / (name + "-" + std::to_string(getpid()));
        std::filesystem::remove_all(base_);
        root_ = base_ / "root";
        std::filesystem::create_directories(root_);
    }
    /// Starts the server on root_.
    void start(server::ServerOptions o = test_options()) {
        o.scene_root = root_.string();
        server_ = start_server(std::move(o));
        stub_ = v1::SceneService::NewStub(channel_to(server_->port()));
    }
    grpc::Status load(const std::string& source, const std::string& id = "", v1::SceneInfo* info = nullptr) {
        return load_scene_call(*stub_, source, id, info);
    }
    void TearDown() override {
        stub_.reset();
        server_.reset();
        std::error_code ec;
        std::filesystem::remove_all(base_, ec);
    }
    std::filesystem::path base_, root_;
    std::unique_ptr<server::Server> server_;
    std::unique_ptr<v1::SceneService::Stub> stub_;
};

}  // namespace catgs::test
