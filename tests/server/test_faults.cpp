// Fault tests: clients killed mid-stream, scenes unloaded under running streams, memory
// running out when a scene is loaded or put on the (simulated) device, a burst of stream opens
// far beyond the admission limit, and bytes on the wire that are not valid messages. After
// each, the server is healthy: health SERVING, no session, lease or buffered frame left
// behind, and a new stream renders. The client's side of faults: test_client_faults.cpp.
#include <arpa/inet.h>
#include <grpcpp/generic/generic_stub.h>
#include <netinet/in.h>
#include <sys/socket.h>

#include <barrier>
#include <filesystem>
#include <random>

#include "fake_device.hpp"
#include "process_util.hpp"
#include "server_test_util.hpp"

namespace catgs::test {
namespace {

namespace fs = std::filesystem;

/// The server is healthy and holds nothing of the streams that went before.
void expect_healthy_and_idle(server::Server& server, int expected_streams = 0) {
    EXPECT_TRUE(serving(server.port()));
    EXPECT_TRUE(eventually([&] { return server.stats().streams_open == expected_streams; }))
        << server.stats().streams_open << " streams open";
    EXPECT_TRUE(eventually([&] { return server.stats().sessions_active == expected_streams; }))
        << server.stats().sessions_active << " sessions active";
    EXPECT_TRUE(eventually([&] {
        for (const auto& scene : server.core().scenes().list())
            if (scene.sessions != 0 && expected_streams == 0) return false;
        return true;
    })) << "a scene lease was left behind";
    if (expected_streams == 0) {
        EXPECT_TRUE(eventually([&] { return server.stats().frames_buffered == 0; }));
    }
    // A new stream renders.
    expect_one_frame(channel_to(server.port()));
}

// ---------------------------------------------------------------------------------------
// A client killed with SIGKILL in the middle of its streams.
// ---------------------------------------------------------------------------------------

TEST(ServerFaults, ClientKilledWithSigkillMidStream) {
    auto server = start_server();
    const std::string address = "127.0.0.1:" + std::to_string(server->port());
    Child client({CATGS_CLIENT_BINARY, "--server", address, "load", "--scene", "city", "--streams", "4", "--duration",
                  "60", "--rate", "30", "--width", "160", "--height", "90", "--trajectory",
                  "builtin:flythrough?frames=300&altitude=40"});
    ASSERT_TRUE(client.started());
    ASSERT_TRUE(eventually([&] { return server->stats().sessions_active == 4 && server->stats().frames_sent >= 20; },
                           std::chrono::milliseconds(30000)))
        << "sessions " << server->stats().sessions_active << ", frames " << server->stats().frames_sent << "\n"
        << client.output();
    client.kill(SIGKILL);
    EXPECT_EQ(client.wait(std::chrono::seconds(10)).value_or(-1), 128 + SIGKILL);
    // The kernel closes the sockets; the server notices (RST), cancels and frees all four.
    expect_healthy_and_idle(*server);
    server::SceneSummary city;
    EXPECT_TRUE(eventually([&] { return server->core().scenes().get("city", &city).ok() && city.sessions == 0; }))
        << city.sessions;
    EXPECT_FALSE(city.unloading);
}

// ---------------------------------------------------------------------------------------
// A scene unloaded while streams use it.
//
// Behaviour (see scene_registry.hpp): UnloadScene marks the scene UNLOADING and returns at
// once (freed = false). Streams already admitted keep their lease and keep getting frames
// until they close; new streams and unary renders on it are refused with FAILED_PRECONDITION
// ("... the scene is being unloaded"); loading the same id again is ALREADY_EXISTS ("still
// unloading"). The scene is freed when its last session closes, and then the id can be
// loaded again. Nothing is ever pulled from under an admitted stream.
// ---------------------------------------------------------------------------------------

TEST(ServerFaults, SceneUnloadedWhileStreamsUseIt) {
    server::ServerOptions o = test_options();
    o.limits.max_sessions = 8;
    auto server = start_server(o);
    auto scenes = v1::SceneService::NewStub(channel_to(server->port()));
    auto load = [&](const std::string& id, v1::SceneInfo* info) {
        return load_scene_call(*scenes, "builtin:city?gaussians=10000&seed=5", id, info);
    };
    v1::SceneInfo info;
    ASSERT_TRUE(load("doomed", &info).ok());
    auto unary = [&](grpc::Status* status) {
        v1::Frame frame;
        const v1::SessionConfig config = session_config(v1::ENCODING_PNG, 0, "doomed");
        *status = render_once(channel_to(server->port()), render_request(config, frame_request(1, uav_path(2)[0], 0)),
                              &frame);
        return frame;
    };
    // A unary render leaves a pooled renderer holding the scene.
    grpc::Status status;
    unary(&status);
    ASSERT_TRUE(status.ok()) << status.error_message();
    EXPECT_EQ(server->stats().pooled_renderers, 1);

    // Three lock-step streams on the scene, each on its own thread.
    constexpr int kStreams = 3;
    std::atomic<bool> stop{false};
    std::atomic<int> frames_after_unload{0};
    std::atomic<bool> unloaded{false};
    std::vector<grpc::Status> finals(kStreams);
    std::vector<std::string> errors(kStreams);
    std::vector<std::thread> threads;
    std::atomic<int> opened{0};
    for (int s = 0; s < kStreams; ++s) {
        threads.emplace_back([&, s] {
            StreamClient client(channel_to(server->port()));
            const auto path = uav_path(30);
            if (!client.open(session_config(v1::ENCODING_JPEG, 0, "doomed"))) return;
            std::uint64_t seq = 0, ack = 0;
            while (!stop) {
                ++seq;
                if (!client.send(frame_request(seq, path[seq % path.size()], ack))) break;
                v1::Frame frame;
                if (!client.stream->Read(&frame)) break;
                if (frame.has_error()) errors[static_cast<std::size_t>(s)] = frame.error().message();
                if (seq == 1) ++opened;
                if (unloaded) ++frames_after_unload;
                ack = frame.sequence();
            }
            finals[static_cast<std::size_t>(s)] = client.close();
        });
    }
    ASSERT_TRUE(eventually([&] { return opened == kStreams; }));

    {
        grpc::ClientContext context;
        v1::UnloadSceneRequest request;
        request.set_scene_id("doomed");
        v1::UnloadSceneResponse response;
        ASSERT_TRUE(scenes->UnloadScene(&context, request, &response).ok());
        EXPECT_FALSE(response.freed());
        EXPECT_EQ(response.scene().state(), v1::SCENE_STATE_UNLOADING);
        EXPECT_EQ(response.scene().sessions(), static_cast<std::uint32_t>(kStreams));
    }
    unloaded = true;
    // The idle pooled renderer does not keep an unloading scene.
    EXPECT_TRUE(eventually([&] { return server->stats().pooled_renderers == 0; }));
    // New work on the scene is refused, with a status that says why.
    StreamClient late(channel_to(server->port()));
    late.open(session_config(v1::ENCODING_JPEG, 0, "doomed"));
    late.send(frame_request(1, uav_path(2)[0], 0));
    status = late.close();
    EXPECT_EQ(status.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
    EXPECT_EQ(status.error_message(), "open.scene_id 'doomed': the scene is being unloaded");
    unary(&status);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
    EXPECT_EQ(status.error_message(), "config.scene_id 'doomed': the scene is being unloaded");
    status = load("doomed", &info);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::ALREADY_EXISTS);
    EXPECT_NE(status.error_message().find("scene_id 'doomed' is still unloading (freed when its 3 session(s) close)"),
              std::string::npos)
        << status.error_message();

    // The admitted streams keep rendering.
    EXPECT_TRUE(eventually([&] { return frames_after_unload >= 3 * kStreams; }, std::chrono::milliseconds(20000)))
        << frames_after_unload;
    stop = true;
    for (auto& t : threads) t.join();
    for (int s = 0; s < kStreams; ++s) {
        EXPECT_TRUE(finals[static_cast<std::size_t>(s)].ok()) << finals[static_cast<std::size_t>(s)].error_message();
        EXPECT_TRUE(errors[static_cast<std::size_t>(s)].empty()) << errors[static_cast<std::size_t>(s)];
    }
    // Freed with its last session; the id is free again.
    EXPECT_TRUE(eventually([&] {
        server::SceneSummary summary;
        return server->core().scenes().get("doomed", &summary).error_code() == grpc::StatusCode::NOT_FOUND;
    }));
    status = load("doomed", &info);
    EXPECT_TRUE(status.ok()) << status.error_message();
    expect_healthy_and_idle(*server);
}

// ---------------------------------------------------------------------------------------
// Memory running out.
// ---------------------------------------------------------------------------------------

/// --max-scene-mb, on the path where the file-size estimate passes and the scene the header
/// declares does not fit at its SH degree: RESOURCE_EXHAUSTED before the Gaussians are
/// allocated, nothing counted.
TEST(ServerFaults, SceneLoadBeyondTheMemoryLimit) {
    const fs::path root = fs::path(CATGS_TEST_TMP) / "oom-root";
    fs::create_directories(root);
    // A PLY of 20000 Gaussians: 5.3 MB on disk (1.3 MB estimated before loading), 4.7 MB loaded.
    write_ply(load_scene("builtin:city?gaussians=20000&seed=6"), (root / "medium.ply").string());
    server::ServerOptions o = test_options();
    o.scene_root = root.string();
    o.limits.max_scene_bytes = 8'000'000;  // the city (4.7 MB) and 3.3 MB more
    auto server = start_server(o);
    BackgroundStream healthy(server->port());
    ASSERT_TRUE(healthy.advances(2));
    auto scenes = v1::SceneService::NewStub(channel_to(server->port()));
    auto load = [&](const std::string& source, const std::string& id) { return load_scene_call(*scenes, source, id); };
    for (int round = 0; round < 2; ++round) {  // twice: nothing of the first attempt remains
        grpc::Status status = load("medium.ply", "medium");
        EXPECT_EQ(status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
        EXPECT_NE(status.error_message().find("max-scene-bytes: loading 'medium.ply' would exceed the limit of 8000000 "
                                              "bytes: medium.ply: 20000 records of SH degree 3 at 236 bytes each "
                                              "exceed the limit of 3280000 bytes"),
                  std::string::npos)
            << status.error_message();
        // The generator's estimate is refused before anything is allocated.
        status = load("builtin:city?gaussians=1000000", "huge");
        EXPECT_EQ(status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
        EXPECT_NE(status.error_message().find("max-scene-bytes: loading 'builtin:city?gaussians=1000000' would exceed "
                                              "the limit of 8000000 bytes (4720000 in use)"),
                  std::string::npos)
            << status.error_message();
    }
    EXPECT_EQ(server->core().scenes().list().size(), 1u);
    EXPECT_EQ(server->stats().out_of_memory, 4u);
    // What fits still loads.
    const grpc::Status status = load("builtin:city?gaussians=10000&seed=2", "fits");
    EXPECT_TRUE(status.ok()) << status.error_message();
    healthy.expect_kept_going();
    expect_healthy_and_idle(*server);
}

/// The device running out of memory when a session puts its scene on it (simulated with
/// FakeDevice: the CUDA backend's error text, one shared copy per scene): the stream, and a
/// unary render, end with RESOURCE_EXHAUSTED naming the scene; other sessions go on; the
/// admission slot and the scene lease are given back.
TEST(ServerFaults, DeviceOutOfMemoryWhenASessionLoadsItsScene) {
    auto device = std::make_shared<FakeDevice>(/*capacity*/ 10'000'000, /*arena bytes per pixel*/ 0);
    server::ServerOptions o = test_options();
    o.renderer_factory = device->factory();
    auto server = start_server(o);
    BackgroundStream healthy(server->port());  // holds the city (4.7 MB) on the device
    ASSERT_TRUE(healthy.advances(2));
    ASSERT_EQ(device->used(), 4'720'000u);
    {
        // 40000 Gaussians: 9.4 MB more than the device has left.
        auto scenes = v1::SceneService::NewStub(channel_to(server->port()));
        // Host memory is not limited here.
        ASSERT_TRUE(load_scene_call(*scenes, "builtin:city?gaussians=40000&seed=7", "big").ok());
    }
    const std::string expected =
        "out-of-memory: the server cannot hold scene 'big' for another session (CUDA error in cudaMalloc"
        "(&scene->positions) at device_buffer.hpp:48: cudaErrorMemoryAllocation: out of memory); retry later or on "
        "another server";
    for (int round = 0; round < 3; ++round) {
        StreamClient client(channel_to(server->port()));
        ASSERT_TRUE(client.open(session_config(v1::ENCODING_JPEG, 0, "big")));
        client.send(frame_request(1, uav_path(2)[0], 0));
        v1::Frame frame;
        EXPECT_FALSE(client.stream->Read(&frame));
        const grpc::Status status = client.stream->Finish();
        EXPECT_EQ(status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << status.error_message();
        EXPECT_EQ(status.error_message(), expected);
    }
    {
        v1::Frame frame;
        const grpc::Status status = render_once(
            channel_to(server->port()),
            render_request(session_config(v1::ENCODING_PNG, 0, "big"), frame_request(1, uav_path(2)[0], 0)), &frame);
        EXPECT_EQ(status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << status.error_message();
        EXPECT_NE(status.error_message().find("out-of-memory: the render failed (CUDA error"), std::string::npos)
            << status.error_message();
    }
    EXPECT_EQ(server->stats().out_of_memory, 4u);
    EXPECT_EQ(device->used(), 4'720'000u);  // nothing of the failed uploads stayed
    healthy.expect_kept_going();
    expect_healthy_and_idle(*server);
    // The city's session is gone; its renderer, idle in the pool, still holds the city.
    ASSERT_TRUE(eventually([&] { return server->stats().pooled_renderers == 1; }));
    EXPECT_EQ(device->used(), 4'720'000u);
    // An idle renderer yields its device memory to a session: the big scene renders, and the
    // city, held by nothing now, has left the device.
    expect_one_frame(channel_to(server->port()), session_config(v1::ENCODING_JPEG, 0, "big"));
    EXPECT_EQ(server->stats().out_of_memory, 4u);
    ASSERT_TRUE(eventually([&] { return device->used() == 9'440'000u; })) << device->used();  // 40000 Gaussians
}

/// A frame that runs out of device memory ends its session, as before, and takes the device's
/// idle pooled renderers with it, so that the client's retry finds their memory free (simulated
/// with FakeDevice: 100 bytes of arenas a pixel, room for the city and one 320x180 renderer).
TEST(ServerFaults, IdleRenderersGoWhenAFrameRunsOutOfDeviceMemory) {
    auto device = std::make_shared<FakeDevice>(/*capacity*/ 11'000'000, /*arena bytes per pixel*/ 100);
    auto server = start_server([&] {
        server::ServerOptions o = test_options();
        o.renderer_factory = device->factory();
        return o;
    }());
    const auto path = uav_path(2);
    {
        // Two sessions at 160x90 at once: two renderers (1.44 MB of arenas each), both pooled.
        StreamClient a(channel_to(server->port())), b(channel_to(server->port()));
        for (StreamClient* client : {&a, &b}) {
            ASSERT_TRUE(client->open(session_config(v1::ENCODING_JPEG)));
            ASSERT_TRUE(client->send(frame_request(1, path[0], 0)));
        }
        for (StreamClient* client : {&a, &b}) {
            v1::Frame frame;
            ASSERT_TRUE(client->stream->Read(&frame));
            ASSERT_FALSE(frame.has_error()) << frame.error().message();
        }
        EXPECT_TRUE(a.close().ok());
        EXPECT_TRUE(b.close().ok());
    }
    ASSERT_TRUE(eventually([&] { return server->stats().pooled_renderers == 2; }));
    EXPECT_EQ(device->used(), 4'720'000u + 2 * 1'440'000u);
    v1::SessionConfig large = session_config(v1::ENCODING_JPEG);
    large.set_width(320);
    large.set_height(180);
    {
        // 320x180 needs 5.76 MB: the pooled renderer it takes grows past the device.
        StreamClient client(channel_to(server->port()));
        ASSERT_TRUE(client.open(large));
        client.send(frame_request(1, uav_path(2, 320, 180)[0], 0));
        const grpc::Status status = client.close();
        EXPECT_EQ(status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << status.error_message();
        EXPECT_NE(status.error_message().find("out-of-memory"), std::string::npos) << status.error_message();
        EXPECT_NE(status.error_message().find("cudaErrorMemoryAllocation"), std::string::npos)
            << status.error_message();
    }
    EXPECT_EQ(server->stats().out_of_memory, 1u);
    // Its renderer (arenas outgrown) and the idle one are gone, and with them the city.
    ASSERT_TRUE(eventually([&] { return device->used() == 0; })) << device->used();
    EXPECT_EQ(server->stats().pooled_renderers, 0);
    // The retry renders: 4.72 MB of scene and 5.76 MB of arenas fit.
    expect_one_frame(channel_to(server->port()), large);
    expect_healthy_and_idle(*server);
}

// ---------------------------------------------------------------------------------------
// 200 concurrent stream opens against 4 session slots.
// ---------------------------------------------------------------------------------------

TEST(ServerFaults, BurstOf200StreamOpensBeyondTheAdmissionLimit) {
    constexpr int kClients = 200;
    server::ServerOptions o = test_options();
    o.limits.max_sessions = 4;
    auto server = start_server(o);
    struct Outcome {
        grpc::Status status;
        int frames = 0;
        double seconds = 0;
    };
    std::vector<Outcome> outcomes(kClients);
    std::barrier start(kClients);
    std::vector<std::thread> threads;
    const auto path = uav_path(4);
    const auto begin = std::chrono::steady_clock::now();
    for (int i = 0; i < kClients; ++i) {
        threads.emplace_back([&, i] {
            grpc::ChannelArguments args = net::client_channel_args();
            args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);  // one connection each, as separate viewers
            auto channel = channel_to(server->port(), args);
            start.arrive_and_wait();
            const auto t0 = std::chrono::steady_clock::now();
            StreamClient client(channel);
            client.context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
            Outcome& out = outcomes[static_cast<std::size_t>(i)];
            if (client.open(session_config(v1::ENCODING_JPEG)) && client.send(frame_request(1, path[i % 4], 0))) {
                v1::Frame frame;
                if (client.stream->Read(&frame) && !frame.has_error() && !frame.data().empty()) ++out.frames;
            }
            out.status = client.close();
            out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        });
    }
    for (auto& t : threads) t.join();
    const double total = std::chrono::duration<double>(std::chrono::steady_clock::now() - begin).count();
    int served = 0, refused = 0, unavailable = 0;
    double slowest = 0;
    for (const Outcome& out : outcomes) {
        slowest = std::max(slowest, out.seconds);
        if (out.status.ok()) {
            ++served;
            EXPECT_EQ(out.frames, 1) << "an admitted stream ended OK without its frame";
        } else if (out.status.error_code() == grpc::StatusCode::RESOURCE_EXHAUSTED) {
            ++refused;
            EXPECT_NE(out.status.error_message().find("max-sessions: the server already runs 4 of 4 sessions; retry "
                                                      "later or on another server"),
                      std::string::npos)
                << out.status.error_message();
        } else if (out.status.error_code() == grpc::StatusCode::UNAVAILABLE) {
            ++unavailable;
            EXPECT_FALSE(out.status.error_message().empty());
        } else {
            ADD_FAILURE() << "unexpected status " << out.status.error_code() << ": " << out.status.error_message();
        }
    }
    std::printf(
        "burst of %d opens: %d served, %d refused (max-sessions), %d unavailable; slowest %.2f s, all in %.2f s\n",
        kClients, served, refused, unavailable, slowest, total);
    EXPECT_GE(served, 4);
    EXPECT_EQ(served + refused + unavailable, kClients);
    EXPECT_LT(slowest, 30.0) << "a stream hung";
    EXPECT_EQ(server->stats().sessions_opened, static_cast<std::uint64_t>(served));
    expect_healthy_and_idle(*server);
}

// ---------------------------------------------------------------------------------------
// Bytes that are not valid messages.
// ---------------------------------------------------------------------------------------

/// One raw call through the generic stub: writes `messages`, reads whatever comes back.
grpc::Status raw_call(const std::shared_ptr<grpc::Channel>& channel, const std::string& method,
                      const std::vector<std::string>& messages, int* responses = nullptr) {
    grpc::GenericStub stub(channel);
    grpc::CompletionQueue cq;
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(20));
    auto call = stub.PrepareCall(&context, method, &cq);
    void* tag = nullptr;
    bool ok = false;
    auto next = [&] {
        EXPECT_TRUE(cq.Next(&tag, &ok));
        return ok;
    };
    call->StartCall(reinterpret_cast<void*>(1));
    next();
    for (const std::string& m : messages) {
        grpc::Slice slice(m);
        grpc::ByteBuffer buffer(&slice, 1);
        call->Write(buffer, reinterpret_cast<void*>(2));
        if (!next()) break;
    }
    call->WritesDone(reinterpret_cast<void*>(3));
    next();
    int n = 0;
    for (;;) {
        grpc::ByteBuffer in;
        call->Read(&in, reinterpret_cast<void*>(4));
        if (!next()) break;
        ++n;
    }
    if (responses) *responses = n;
    grpc::Status status;
    call->Finish(&status, reinterpret_cast<void*>(5));
    next();
    cq.Shutdown();
    while (cq.Next(&tag, &ok)) {
    }
    return status;
}

template <typename Message>
bool parses_as(const std::string& bytes) {
    Message m;
    return m.ParseFromString(bytes);
}

TEST(ServerFaults, MalformedProtobufOnEveryMethod) {
    const std::uint64_t seed = test_seed("MalformedProtobufOnEveryMethod");
    std::mt19937_64 random(seed);
    auto server = start_server();
    BackgroundStream healthy(server->port());
    ASSERT_TRUE(healthy.advances(2));
    auto channel = channel_to(server->port());

    struct Method {
        std::string path, type;
        std::function<bool(const std::string&)> parses;
    };
    const std::vector<Method> methods = {
        {"/catgs.v1.RenderService/Stream", "StreamRequest", parses_as<v1::StreamRequest>},
        {"/catgs.v1.RenderService/Render", "RenderRequest", parses_as<v1::RenderRequest>},
        {"/catgs.v1.SceneService/LoadScene", "LoadSceneRequest", parses_as<v1::LoadSceneRequest>},
        {"/catgs.v1.SceneService/ListScenes", "ListScenesRequest", parses_as<v1::ListScenesRequest>},
        {"/catgs.v1.SceneService/UnloadScene", "UnloadSceneRequest", parses_as<v1::UnloadSceneRequest>},
        {"/catgs.v1.SceneService/GetScene", "GetSceneRequest", parses_as<v1::GetSceneRequest>},
    };
    // Always malformed: a length running past the end, wire types 6 and 7, a varint of 11
    // bytes, field number 0, an end-group without a start.
    std::vector<std::string> garbage = {std::string("\x0a\x7f"
                                                    "ab",
                                                    4),
                                        std::string("\x0e", 1),
                                        std::string("\x0f", 1),
                                        std::string(11, '\xff'),
                                        std::string("\x00\x01", 2),
                                        std::string("\x0c", 1)};
    int random_cases = 0, random_parsed = 0;
    for (int i = 0; i < 12; ++i) {
        std::string bytes(1 + random() % 300, '\0');
        for (char& c : bytes) c = static_cast<char>(random() & 0xff);
        garbage.push_back(bytes);
    }
    for (const Method& m : methods) {
        for (std::size_t g = 0; g < garbage.size(); ++g) {
            const std::string& bytes = garbage[g];
            if (m.parses(bytes)) {
                EXPECT_GE(g, 6u) << "fixed garbage #" << g << " parses as " << m.type;
                ++random_parsed;  // random bytes that happen to be a valid message: not this test's case
                continue;
            }
            if (g >= 6) ++random_cases;
            SCOPED_TRACE(m.path + ", garbage #" + std::to_string(g) + " (" + std::to_string(bytes.size()) + " bytes)");
            const grpc::Status status = raw_call(channel, m.path, {bytes});
            EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << status.error_message();
            EXPECT_EQ(status.error_message(), "request: " + std::to_string(bytes.size()) +
                                                  " bytes that are not a valid catgs.v1." + m.type +
                                                  " message (malformed protobuf)");
        }
    }
    std::printf("malformed messages: %d random cases sent, %d random buffers parsed and were skipped\n", random_cases,
                random_parsed);
    EXPECT_GT(random_cases, 0);

    // Mid-stream: a good session whose third message is garbage ends with INVALID_ARGUMENT,
    // not as a clean half-close (which would render and end OK).
    std::string open, frame;
    ASSERT_TRUE(open_message(session_config(v1::ENCODING_JPEG)).SerializeToString(&open));
    ASSERT_TRUE(frame_message(frame_request(1, uav_path(2)[0], 0)).SerializeToString(&frame));
    int responses = 0;
    const grpc::Status status = raw_call(channel, "/catgs.v1.RenderService/Stream",
                                         {open, frame,
                                          std::string("\x0a\x7f"
                                                      "ab",
                                                      4)},
                                         &responses);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << status.error_message();
    EXPECT_EQ(status.error_message(),
              "request: 4 bytes that are not a valid catgs.v1.StreamRequest message (malformed protobuf)");
    // A method that does not exist.
    const grpc::Status unknown = raw_call(channel, "/catgs.v1.RenderService/Explode", {"x"});
    EXPECT_EQ(unknown.error_code(), grpc::StatusCode::UNIMPLEMENTED) << unknown.error_message();

    healthy.expect_kept_going();
    expect_healthy_and_idle(*server);
}

/// Not even HTTP/2: random bytes on a raw TCP connection, with and without the HTTP/2
/// connection preface. The server drops the connection and carries on.
TEST(ServerFaults, GarbageOnARawConnection) {
    const std::uint64_t seed = test_seed("GarbageOnARawConnection");
    std::mt19937_64 random(seed);
    auto server = start_server();
    BackgroundStream healthy(server->port());
    ASSERT_TRUE(healthy.advances(2));
    for (int round = 0; round < 4; ++round) {
        const int fd = socket(AF_INET, SOCK_STREAM, 0);
        ASSERT_GE(fd, 0);
        sockaddr_in addr{};
        addr.sin_family = AF_INET;
        addr.sin_port = htons(static_cast<std::uint16_t>(server->port()));
        addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
        ASSERT_EQ(connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr), 0);
        timeval timeout{1, 0};
        setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &timeout, sizeof timeout);
        std::string bytes = round % 2 ? std::string("PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n") : std::string();
        bytes.resize(bytes.size() + 4096);
        for (std::size_t i = bytes.size() - 4096; i < bytes.size(); ++i) bytes[i] = static_cast<char>(random() & 0xff);
        [[maybe_unused]] const ssize_t sent = send(fd, bytes.data(), bytes.size(), MSG_NOSIGNAL);
        char buffer[1024];
        int reads = 0;
        while (recv(fd, buffer, sizeof buffer, 0) > 0 && ++reads < 100) {
        }
        close(fd);
    }
    healthy.expect_kept_going();
    expect_healthy_and_idle(*server);
}

}  // namespace
}  // namespace catgs::test
