// Health, reflection, graceful shutdown, SceneService, admission control, authentication and
// the catgs-server binary itself.
#include <google/protobuf/descriptor.pb.h>
#include <google/protobuf/dynamic_message.h>
#include <grpcpp/generic/generic_stub.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>

#include "server_test_util.hpp"

namespace catgs::test {
namespace {

namespace fs = std::filesystem;

TEST(ServerAdmin, HealthServesEveryService) {
    auto server = start_server();
    EXPECT_EQ(health(server->port(), ""), HealthStatus::SERVING);
    EXPECT_EQ(health(server->port(), "catgs.v1.RenderService"), HealthStatus::SERVING);
    EXPECT_EQ(health(server->port(), "catgs.v1.SceneService"), HealthStatus::SERVING);
    grpc::Status status;
    health(server->port(), "no.such.Service", &status);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::NOT_FOUND);
}

/// grpc.reflection.v1alpha through a dynamic descriptor pool built from grpc-proto's
/// reflection.proto (compiled to a descriptor set at build time): generated v1alpha classes would clash with the copies
/// inside libgrpc++_reflection.so (the same message names registered twice abort at start-up).
TEST(ServerAdmin, ReflectionListsTheServices) {
    auto server = start_server();
    using namespace google::protobuf;
    FileDescriptorSet set;
    {
        std::ifstream in(CATGS_REFLECTION_DESC, std::ios::binary);
        ASSERT_TRUE(set.ParseFromIstream(&in)) << CATGS_REFLECTION_DESC;
    }
    DescriptorPool pool;
    for (const FileDescriptorProto& file : set.file()) ASSERT_NE(pool.BuildFile(file), nullptr) << file.name();
    const Descriptor* request_type = pool.FindMessageTypeByName("grpc.reflection.v1alpha.ServerReflectionRequest");
    const Descriptor* response_type = pool.FindMessageTypeByName("grpc.reflection.v1alpha.ServerReflectionResponse");
    ASSERT_TRUE(request_type && response_type);
    DynamicMessageFactory factory(&pool);
    std::unique_ptr<Message> request(factory.GetPrototype(request_type)->New());
    request->GetReflection()->SetString(request.get(), request_type->FindFieldByName("list_services"), "*");
    std::string bytes;
    ASSERT_TRUE(request->SerializeToString(&bytes));

    // One raw bidi call on a completion queue: write the request, read one response.
    grpc::GenericStub stub(channel_to(server->port()));
    grpc::CompletionQueue cq;
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
    auto call = stub.PrepareCall(&context, "/grpc.reflection.v1alpha.ServerReflection/ServerReflectionInfo", &cq);
    void* tag = nullptr;
    bool ok = false;
    auto step = [&](int id) {
        ASSERT_TRUE(cq.Next(&tag, &ok));
        ASSERT_EQ(tag, reinterpret_cast<void*>(static_cast<std::intptr_t>(id)));
        ASSERT_TRUE(ok) << "step " << id;
    };
    call->StartCall(reinterpret_cast<void*>(1));
    step(1);
    grpc::Slice slice(bytes);
    grpc::ByteBuffer out(&slice, 1);
    call->Write(out, reinterpret_cast<void*>(2));
    step(2);
    grpc::ByteBuffer in;
    call->Read(&in, reinterpret_cast<void*>(3));
    step(3);
    call->WritesDone(reinterpret_cast<void*>(4));
    step(4);
    grpc::Status status;
    call->Finish(&status, reinterpret_cast<void*>(5));
    ASSERT_TRUE(cq.Next(&tag, &ok));
    EXPECT_TRUE(status.ok()) << status.error_message();

    std::vector<grpc::Slice> slices;
    ASSERT_TRUE(in.Dump(&slices).ok());
    std::string received;
    for (const auto& s : slices) received.append(reinterpret_cast<const char*>(s.begin()), s.size());
    std::unique_ptr<Message> response(factory.GetPrototype(response_type)->New());
    ASSERT_TRUE(response->ParseFromString(received));
    const std::string text = response->DebugString();
    EXPECT_NE(text.find("catgs.v1.RenderService"), std::string::npos) << text;
    EXPECT_NE(text.find("catgs.v1.SceneService"), std::string::npos) << text;
    cq.Shutdown();
    while (cq.Next(&tag, &ok)) {
    }
}

TEST(ServerAdmin, ShutdownDrainsOpenStreamsWithUnavailable) {
    server::ServerOptions o = test_options();
    o.health_address = "127.0.0.1:0";
    auto server = start_server(o);
    ASSERT_GT(server->health_port(), 0);
    EXPECT_EQ(health(server->health_port(), "catgs.v1.RenderService"), HealthStatus::SERVING);

    const auto path = uav_path(5);
    StreamClient reading(channel_to(server->port()));
    ASSERT_TRUE(reading.open(session_config(v1::ENCODING_JPEG)));
    ASSERT_TRUE(reading.send(frame_request(1, path[0], 0)));
    v1::Frame frame;
    ASSERT_TRUE(reading.stream->Read(&frame));
    // A second stream that never reads or acknowledges.
    StreamClient stuck(channel_to(server->port()));
    ASSERT_TRUE(stuck.open(session_config(v1::ENCODING_JPEG)));
    for (int i = 1; i <= 5; ++i) stuck.send(frame_request(static_cast<std::uint64_t>(i), path[i % 5], 0));

    const auto begin = std::chrono::steady_clock::now();
    server->begin_shutdown();
    EXPECT_EQ(health(server->health_port(), "catgs.v1.RenderService"), HealthStatus::NOT_SERVING);
    EXPECT_EQ(health(server->port(), ""), HealthStatus::NOT_SERVING);
    grpc::Status status = reading.finish();
    EXPECT_EQ(status.error_code(), grpc::StatusCode::UNAVAILABLE);
    EXPECT_NE(status.error_message().find("shutting down: reconnect"), std::string::npos) << status.error_message();
    // New sessions are refused.
    StreamClient late(channel_to(server->port()));
    late.open(session_config(v1::ENCODING_JPEG));
    status = late.close();
    EXPECT_EQ(status.error_code(), grpc::StatusCode::UNAVAILABLE);
    EXPECT_NE(status.error_message().find("shutting down"), std::string::npos) << status.error_message();

    server->shutdown(std::chrono::milliseconds(1500));
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - begin).count();
    EXPECT_LT(seconds, 4.0);
    // The server is gone: what the stream that never read gets now was decided without its
    // reading, and it is the shutdown message too (the cancel carries it past the unread frame).
    status = stuck.finish();
    EXPECT_EQ(status.error_code(), grpc::StatusCode::UNAVAILABLE) << status.error_message();
    EXPECT_NE(status.error_message().find("shutting down: reconnect"), std::string::npos) << status.error_message();
}

class SceneServiceTest : public SceneRootTest {
protected:
    void SetUp() override {
        make_root("scene-root");
        // A small scene file under the root, and one outside it.
        Scene small = load_scene("builtin:city?gaussians=10000&seed=3");
        write_ply(small, (root_ / "small.ply").string());
        write_ply(small, (base_ / "outside.ply").string());
        server::ServerOptions o = test_options();
        o.limits.max_scene_bytes = 10 * 1000 * 1000;  // city (4.7 MB) + small (2.4 MB) fit; 20 MB more do not
        start(o);
    }
    grpc::Status get(const std::string& id, v1::SceneInfo* info) {
        grpc::ClientContext context;
        v1::GetSceneRequest request;
        request.set_scene_id(id);
        return stub_->GetScene(&context, request, info);
    }
};

TEST_F(SceneServiceTest, ListGetLoadUnload) {
    v1::SceneInfo info;
    ASSERT_TRUE(get("city", &info).ok());
    EXPECT_EQ(info.gaussian_count(), test_scene()->count());
    EXPECT_EQ(info.sh_degree(), 3);
    EXPECT_DOUBLE_EQ(info.bounds().min().x(), test_scene()->bounds.min[0]);
    EXPECT_DOUBLE_EQ(info.bounds().max().z(), test_scene()->bounds.max[2]);
    EXPECT_EQ(info.host_bytes(), test_scene()->bytes());
    EXPECT_EQ(info.device_bytes(), 0u);  // CPU backend
    EXPECT_EQ(info.state(), v1::SCENE_STATE_READY);

    ASSERT_TRUE(load("small.ply", "", &info).ok());
    EXPECT_EQ(info.scene_id(), "small");
    EXPECT_EQ(info.gaussian_count(), 10000u);
    {
        grpc::ClientContext context;
        v1::ListScenesResponse list;
        ASSERT_TRUE(stub_->ListScenes(&context, {}, &list).ok());
        ASSERT_EQ(list.scenes_size(), 2);
        EXPECT_EQ(list.scenes(0).scene_id(), "city");
        EXPECT_EQ(list.scenes(1).scene_id(), "small");
    }
    grpc::Status status = load("small.ply", "", &info);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::ALREADY_EXISTS);
    EXPECT_NE(status.error_message().find("scene_id 'small' is already loaded"), std::string::npos);

    // A stream holds the scene; unloading waits for it.
    StreamClient client(channel_to(server_->port()));
    ASSERT_TRUE(client.open(session_config(v1::ENCODING_JPEG, 0, "small")));
    ASSERT_TRUE(client.send(frame_request(1, uav_path(2)[0], 0)));
    v1::Frame frame;
    ASSERT_TRUE(client.stream->Read(&frame));
    ASSERT_TRUE(get("small", &info).ok());
    EXPECT_EQ(info.sessions(), 1u);
    {
        grpc::ClientContext context;
        v1::UnloadSceneRequest request;
        request.set_scene_id("small");
        v1::UnloadSceneResponse response;
        ASSERT_TRUE(stub_->UnloadScene(&context, request, &response).ok());
        EXPECT_FALSE(response.freed());
        EXPECT_EQ(response.scene().state(), v1::SCENE_STATE_UNLOADING);
    }
    StreamClient refused(channel_to(server_->port()));
    refused.open(session_config(v1::ENCODING_JPEG, 0, "small"));
    status = refused.close();
    EXPECT_EQ(status.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
    EXPECT_NE(status.error_message().find("open.scene_id 'small': the scene is being unloaded"), std::string::npos)
        << status.error_message();
    // The open stream still renders, then closes; the scene goes with it.
    ASSERT_TRUE(client.send(frame_request(2, uav_path(2)[1], 1)));
    ASSERT_TRUE(client.stream->Read(&frame));
    EXPECT_FALSE(frame.has_error());
    EXPECT_TRUE(client.close().ok());
    EXPECT_TRUE(eventually([&] { return get("small", &info).error_code() == grpc::StatusCode::NOT_FOUND; }));
}

TEST_F(SceneServiceTest, PathsMayNotLeaveTheSceneRoot) {
    v1::SceneInfo info;
    grpc::Status status = load("../outside.ply", "", &info);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_NE(status.error_message().find("source '../outside.ply': path leaves the scene root"), std::string::npos)
        << status.error_message();
    status = load((root_ / "small.ply").string(), "", &info);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_NE(status.error_message().find("expected a path relative to the scene root"), std::string::npos)
        << status.error_message();
    fs::remove(root_ / "link.ply");
    fs::create_symlink(root_.parent_path() / "outside.ply", root_ / "link.ply");
    status = load("link.ply", "", &info);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_NE(status.error_message().find("path leaves the scene root"), std::string::npos) << status.error_message();
    status = load("missing.ply", "", &info);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_NE(status.error_message().find("no such file under the scene root"), std::string::npos);
    status = load("builtin:city?gaussians=10000", "bad id!", &info);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_NE(status.error_message().find("scene_id 'bad id!'"), std::string::npos);
}

/// "." and ".." pass the character rule but name directories: refused, whether given or
/// derived from the file name ("...ply" has the stem ".."); ids that merely contain dots load.
TEST_F(SceneServiceTest, DotAndDotDotAreNotSceneIds) {
    v1::SceneInfo info;
    for (const std::string id : {".", ".."}) {
        SCOPED_TRACE(id);
        const grpc::Status status = load("builtin:city?gaussians=10000", id, &info);
        EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
        EXPECT_NE(status.error_message().find("scene_id '" + id + "': '.' and '..' are not scene ids"),
                  std::string::npos)
            << status.error_message();
    }
    fs::copy_file(root_ / "small.ply", root_ / "...ply");
    grpc::Status status = load("...ply", "", &info);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_NE(status.error_message().find("scene_id '..': '.' and '..' are not scene ids"), std::string::npos)
        << status.error_message();
    status = load("builtin:city?gaussians=10000", "...", &info);
    EXPECT_TRUE(status.ok()) << status.error_message();
    EXPECT_EQ(info.scene_id(), "...");
}

TEST_F(SceneServiceTest, SceneBytesLimit) {
    v1::SceneInfo info;
    const grpc::Status status = load("builtin:city?gaussians=100000&seed=2", "big", &info);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
    EXPECT_NE(status.error_message().find("max-scene-bytes"), std::string::npos) << status.error_message();
    EXPECT_TRUE(load("builtin:city?gaussians=10000&seed=2", "fits", &info).ok());
}

TEST(ServerAdmission, MaxSessions) {
    server::ServerOptions o = test_options();
    o.limits.max_sessions = 1;
    auto server = start_server(o);
    StreamClient first(channel_to(server->port()));
    ASSERT_TRUE(first.open(session_config(v1::ENCODING_JPEG)));
    ASSERT_TRUE(first.send(frame_request(1, uav_path(2)[0], 0)));
    v1::Frame frame;
    ASSERT_TRUE(first.stream->Read(&frame));
    StreamClient second(channel_to(server->port()));
    second.open(session_config(v1::ENCODING_JPEG));
    const grpc::Status status = second.close();
    EXPECT_EQ(status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
    EXPECT_NE(status.error_message().find("max-sessions: the server already runs 1 of 1 sessions"), std::string::npos)
        << status.error_message();
    EXPECT_TRUE(first.close().ok());
    // The slot is free again.
    EXPECT_TRUE(eventually([&] { return server->stats().sessions_active == 0; }));
    StreamClient third(channel_to(server->port()));
    ASSERT_TRUE(third.open(session_config(v1::ENCODING_JPEG)));
    ASSERT_TRUE(third.send(frame_request(1, uav_path(2)[0], 0)));
    ASSERT_TRUE(third.stream->Read(&frame));
    EXPECT_TRUE(third.close().ok());
}

TEST(ServerAuth, BearerTokenIsRequiredExceptForHealth) {
    server::ServerOptions o = test_options();
    o.bearer_token = "s3cret";
    auto server = start_server(o);
    EXPECT_EQ(health(server->port(), ""), HealthStatus::SERVING);
    for (const std::string& header : {std::string(), std::string("Bearer wrong"), std::string("Bearer s3cret")}) {
        StreamClient client(channel_to(server->port()), header);
        client.open(session_config(v1::ENCODING_JPEG));
        client.send(frame_request(1, uav_path(2)[0], 0));
        v1::Frame frame;
        const bool got = client.stream->Read(&frame);
        const grpc::Status status = client.close();
        if (header == "Bearer s3cret") {
            EXPECT_TRUE(got);
            EXPECT_TRUE(status.ok()) << status.error_message();
        } else {
            EXPECT_EQ(status.error_code(), grpc::StatusCode::UNAUTHENTICATED) << header;
            EXPECT_NE(status.error_message().find(header.empty() ? "missing metadata 'authorization: Bearer <token>'"
                                                                 : "wrong bearer token"),
                      std::string::npos)
                << status.error_message();
        }
    }
    auto scenes = v1::SceneService::NewStub(channel_to(server->port()));
    grpc::ClientContext context;
    v1::ListScenesResponse list;
    EXPECT_EQ(scenes->ListScenes(&context, {}, &list).error_code(), grpc::StatusCode::UNAUTHENTICATED);
}

/// The binary: starts on an ephemeral port, prints it, serves, and exits 0 on SIGTERM (after a
/// short drain: test_drain.cpp checks the default one step by step).
TEST(ServerBinary, StartsPrintsItsPortAndStopsOnSigterm) {
    int out[2];
    ASSERT_EQ(pipe(out), 0);
    const pid_t pid = fork();
    ASSERT_GE(pid, 0);
    if (pid == 0) {
        dup2(out[1], STDOUT_FILENO);
        close(out[0]);
        execl(CATGS_SERVER_BINARY, CATGS_SERVER_BINARY, "--address", "127.0.0.1:0", "--backend", "cpu", "--scene",
              "builtin:city?gaussians=10000&seed=1", "--render-threads", "1", "--log-level", "info", "--drain-ms",
              "500", nullptr);
        _exit(127);
    }
    close(out[1]);
    FILE* stream = fdopen(out[0], "r");
    char line[256] = {};
    ASSERT_NE(fgets(line, sizeof line, stream), nullptr);
    int port = 0;
    ASSERT_EQ(std::sscanf(line, "catgs-server: listening on port %d", &port), 1) << line;
    EXPECT_EQ(health(port, "catgs.v1.RenderService"), HealthStatus::SERVING);
    auto client = std::make_unique<StreamClient>(channel_to(port));
    ASSERT_TRUE(client->open(session_config(v1::ENCODING_JPEG)));
    ASSERT_TRUE(client->send(frame_request(1, uav_path(2)[0], 0)));
    v1::Frame frame;
    ASSERT_TRUE(client->stream->Read(&frame));
    EXPECT_FALSE(frame.has_error()) << frame.error().message();

    const auto begin = std::chrono::steady_clock::now();
    ASSERT_EQ(kill(pid, SIGTERM), 0);
    const grpc::Status status = client->finish();
    EXPECT_EQ(status.error_code(), grpc::StatusCode::UNAVAILABLE);
    // Closes the connection: an idle synchronous client reads gRPC's GOAWAY only when its
    // backup poller runs (every 5 s), and the server waits for it up to --shutdown-grace-ms.
    client.reset();
    int wstatus = 0;
    ASSERT_EQ(waitpid(pid, &wstatus, 0), pid);
    EXPECT_TRUE(WIFEXITED(wstatus));
    EXPECT_EQ(WEXITSTATUS(wstatus), 0);
    EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - begin).count(), 6.0);
    fclose(stream);
}

TEST(ServerBinary, BadFlagsExitWithTwo) {
    const pid_t pid = fork();
    ASSERT_GE(pid, 0);
    if (pid == 0) {
        execl(CATGS_SERVER_BINARY, CATGS_SERVER_BINARY, "--address", "127.0.0.1:0", "--backend", "quantum", nullptr);
        _exit(127);
    }
    int wstatus = 0;
    ASSERT_EQ(waitpid(pid, &wstatus, 0), pid);
    EXPECT_EQ(WEXITSTATUS(wstatus), 2);
}

}  // namespace
}  // namespace catgs::test
