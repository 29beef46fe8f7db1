// Security: TLS with certificates made at test time (make_test_certs.sh, openssl CLI), mutual
// TLS, bearer tokens on every method, the plaintext health listener, reflection behind a
// token, and scene paths confined to the scene root.
#include <grpcpp/generic/generic_stub.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>

#include "process_util.hpp"
#include "server_test_util.hpp"

namespace catgs::test {
namespace {

namespace fs = std::filesystem;

std::string read_text(const fs::path& path) {
    std::ifstream in(path, std::ios::binary);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
}

class TlsTest : public ::testing::Test {
protected:
    static void SetUpTestSuite() {
        // Per process: ctest runs the tests of this suite in parallel processes.
        dir_ = fs::path(CATGS_TEST_TMP) / ("certs-" + std::to_string(getpid()));
        fs::remove_all(dir_);
        const std::string command = "bash '" CATGS_CERT_SCRIPT "' '" + dir_.string() + "' > /dev/null";
        ASSERT_EQ(std::system(command.c_str()), 0) << command << " failed (is openssl installed?)";
    }
    static void TearDownTestSuite() {
        std::error_code ec;
        fs::remove_all(dir_, ec);
    }
    static fs::path cert(const std::string& name) { return dir_ / name; }

    static server::ServerOptions tls_options(bool mutual) {
        server::ServerOptions o = test_options();
        o.tls_cert_file = cert("server.crt").string();
        o.tls_key_file = cert("server.key").string();
        if (mutual) o.tls_client_ca_file = cert("ca.crt").string();
        return o;
    }
    /// A TLS channel trusting `ca`, with a client certificate when `client` names one.
    static std::shared_ptr<grpc::Channel> tls_channel(int port, const std::string& ca = "ca.crt",
                                                      const std::string& client = "") {
        grpc::SslCredentialsOptions ssl;
        ssl.pem_root_certs = read_text(cert(ca));
        if (!client.empty()) {
            ssl.pem_cert_chain = read_text(cert(client + ".crt"));
            ssl.pem_private_key = read_text(cert(client + ".key"));
        }
        return grpc::CreateCustomChannel("127.0.0.1:" + std::to_string(port), grpc::SslCredentials(ssl),
                                         net::client_channel_args());
    }
    /// Opens a stream, asks for one frame; the frame count and the final status.
    static grpc::Status one_frame(const std::shared_ptr<grpc::Channel>& channel, bool* got_frame,
                                  const std::string& authorization = "") {
        StreamClient client(channel, authorization);
        client.context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(20));
        client.open(session_config(v1::ENCODING_JPEG));
        client.send(frame_request(1, uav_path(2)[0], 0));
        v1::Frame frame;
        *got_frame = client.stream->Read(&frame) && !frame.has_error() && !frame.data().empty();
        return client.close();
    }
    static fs::path dir_;
};
fs::path TlsTest::dir_;

TEST_F(TlsTest, StreamWorksOverTlsWithTheCa) {
    auto server = start_server(tls_options(false));
    bool got = false;
    const grpc::Status status = one_frame(tls_channel(server->port()), &got);
    EXPECT_TRUE(status.ok()) << status.error_message();
    EXPECT_TRUE(got);
    // Unary calls too.
    auto scenes = v1::SceneService::NewStub(tls_channel(server->port()));
    grpc::ClientContext context;
    v1::ListScenesResponse list;
    ASSERT_TRUE(scenes->ListScenes(&context, {}, &list).ok());
    EXPECT_EQ(list.scenes_size(), 1);
}

TEST_F(TlsTest, PlaintextClientAndUntrustingClientsAreRefused) {
    auto server = start_server(tls_options(false));
    bool got = true;
    grpc::Status status = one_frame(channel_to(server->port()), &got);
    EXPECT_FALSE(got);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::UNAVAILABLE) << status.error_message();
    EXPECT_FALSE(status.error_message().empty());
    std::printf("plaintext client to TLS server: %s\n", status.error_message().c_str());
    // A client that trusts another CA rejects the server's certificate.
    got = true;
    status = one_frame(tls_channel(server->port(), "rogue-ca.crt"), &got);
    EXPECT_FALSE(got);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::UNAVAILABLE) << status.error_message();
    EXPECT_FALSE(status.error_message().empty());
    std::printf("client trusting another CA: %s\n", status.error_message().c_str());
    EXPECT_EQ(server->stats().sessions_opened, 0u);
}

TEST_F(TlsTest, MutualTlsRequiresAClientCertificateFromTheCa) {
    auto server = start_server(tls_options(true));
    for (const std::string client : {"", "rogue"}) {
        SCOPED_TRACE("client certificate: " + (client.empty() ? std::string("none") : client));
        bool got = true;
        const grpc::Status status = one_frame(tls_channel(server->port(), "ca.crt", client), &got);
        EXPECT_FALSE(got);
        EXPECT_EQ(status.error_code(), grpc::StatusCode::UNAVAILABLE) << status.error_message();
        EXPECT_FALSE(status.error_message().empty());
        std::printf("mTLS with client certificate '%s': %s\n", client.c_str(), status.error_message().c_str());
    }
    EXPECT_EQ(server->stats().sessions_opened, 0u);
    bool got = false;
    const grpc::Status status = one_frame(tls_channel(server->port(), "ca.crt", "client"), &got);
    EXPECT_TRUE(status.ok()) << status.error_message();
    EXPECT_TRUE(got);
}

/// Every method of both services answers UNAUTHENTICATED without the token, with a message
/// that says what is missing or wrong; health stays open, on the TLS port and on the
/// plaintext health port, which serves nothing else.
TEST_F(TlsTest, TokensOnEveryMethodHealthWithoutToken) {
    server::ServerOptions o = tls_options(false);
    o.bearer_token = "s3cret-token";
    o.health_address = "127.0.0.1:0";
    auto server = start_server(o);
    auto channel = tls_channel(server->port());
    struct Header {
        std::string value, message;
    };
    const std::vector<Header> bad = {
        {"", "authorization: missing metadata 'authorization: Bearer <token>'"},
        {"Bearer wrong", "authorization: wrong bearer token"},
        {"Bearer s3cret-token-and-more", "authorization: wrong bearer token"},
        {"Basic s3cret-token", "authorization: wrong bearer token"},
    };
    auto render = v1::RenderService::NewStub(channel);
    auto scenes = v1::SceneService::NewStub(channel);
    for (const Header& h : bad) {
        SCOPED_TRACE("authorization '" + h.value + "'");
        auto context = [&] {
            auto c = std::make_unique<grpc::ClientContext>();
            if (!h.value.empty()) c->AddMetadata("authorization", h.value);
            c->set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
            return c;
        };
        std::vector<std::pair<std::string, grpc::Status>> results;
        bool got = true;
        results.emplace_back("Stream", one_frame(channel, &got, h.value));
        EXPECT_FALSE(got);
        {
            const v1::RenderRequest request =
                render_request(session_config(v1::ENCODING_PNG), frame_request(1, uav_path(2)[0], 0));
            v1::Frame frame;
            auto c = context();
            results.emplace_back("Render", render->Render(c.get(), request, &frame));
        }
        {
            v1::LoadSceneRequest request;
            request.set_source("builtin:city?gaussians=10000");
            v1::SceneInfo info;
            auto c = context();
            results.emplace_back("LoadScene", scenes->LoadScene(c.get(), request, &info));
        }
        {
            v1::ListScenesResponse list;
            auto c = context();
            results.emplace_back("ListScenes", scenes->ListScenes(c.get(), {}, &list));
        }
        {
            v1::UnloadSceneRequest request;
            request.set_scene_id("city");
            v1::UnloadSceneResponse response;
            auto c = context();
            results.emplace_back("UnloadScene", scenes->UnloadScene(c.get(), request, &response));
        }
        {
            v1::GetSceneRequest request;
            request.set_scene_id("city");
            v1::SceneInfo info;
            auto c = context();
            results.emplace_back("GetScene", scenes->GetScene(c.get(), request, &info));
        }
        for (const auto& [method, status] : results) {
            EXPECT_EQ(status.error_code(), grpc::StatusCode::UNAUTHENTICATED)
                << method << ": " << status.error_message();
            EXPECT_EQ(status.error_message(), h.message) << method;
        }
    }
    // Nothing happened: the scene is still there, no session was opened.
    server::SceneSummary city;
    EXPECT_TRUE(server->core().scenes().get("city", &city).ok());
    EXPECT_FALSE(city.unloading);
    EXPECT_EQ(server->stats().sessions_opened, 0u);
    // The right token works.
    bool got = false;
    const grpc::Status status = one_frame(channel, &got, "Bearer s3cret-token");
    EXPECT_TRUE(status.ok()) << status.error_message();
    EXPECT_TRUE(got);

    // Health: no token needed, on the TLS port (over TLS) and on the plaintext health port.
    EXPECT_EQ(health(channel, ""), HealthStatus::SERVING);
    EXPECT_EQ(health(channel, "catgs.v1.RenderService"), HealthStatus::SERVING);
    ASSERT_GT(server->health_port(), 0);
    auto health_channel = channel_to(server->health_port());
    EXPECT_EQ(health(health_channel, ""), HealthStatus::SERVING);
    EXPECT_EQ(health(health_channel, "catgs.v1.SceneService"), HealthStatus::SERVING);
    // The TLS port does not speak plaintext, not even for health.
    grpc::Status plain;
    EXPECT_EQ(health(channel_to(server->port()), "", &plain), HealthStatus::UNKNOWN);
    EXPECT_EQ(plain.error_code(), grpc::StatusCode::UNAVAILABLE) << plain.error_message();
    // The health port serves nothing but health: no rendering around TLS and the token.
    {
        auto stub = v1::SceneService::NewStub(health_channel);
        grpc::ClientContext c;
        c.AddMetadata("authorization", "Bearer s3cret-token");
        v1::ListScenesResponse list;
        const grpc::Status s = stub->ListScenes(&c, {}, &list);
        EXPECT_EQ(s.error_code(), grpc::StatusCode::UNIMPLEMENTED) << s.error_message();
        EXPECT_NE(s.error_message().find("this port serves only grpc.health.v1.Health"), std::string::npos)
            << s.error_message();
    }
    // Reflection would answer without a token: it is off.
    {
        grpc::GenericStub stub(channel);
        grpc::CompletionQueue cq;
        grpc::ClientContext c;
        c.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
        grpc::ByteBuffer request, response;
        auto call =
            stub.PrepareUnaryCall(&c, "/grpc.reflection.v1alpha.ServerReflection/ServerReflectionInfo", request, &cq);
        call->StartCall();
        grpc::Status s;
        call->Finish(&response, &s, reinterpret_cast<void*>(1));
        void* tag = nullptr;
        bool ok = false;
        ASSERT_TRUE(cq.Next(&tag, &ok));
        EXPECT_EQ(s.error_code(), grpc::StatusCode::UNIMPLEMENTED) << s.error_message();
        cq.Shutdown();
        while (cq.Next(&tag, &ok)) {
        }
    }
}

/// The binaries: catgs-server with TLS, mTLS, a token file and a health port; catgs-client
/// with the matching flags streams, and fails with the documented exit codes otherwise.
TEST_F(TlsTest, BinariesWithMutualTlsAndToken) {
    const fs::path token = dir_ / "token";
    {
        std::ofstream out(token);
        out << "binary-token\n";
    }
    const fs::path bad_token = dir_ / "bad-token";
    {
        std::ofstream out(bad_token);
        out << "nope\n";
    }
    Child server({CATGS_SERVER_BINARY, "--address", "127.0.0.1:0", "--health-address", "127.0.0.1:0", "--backend",
                  "cpu", "--scene", "city=builtin:city?gaussians=10000&seed=1", "--render-threads", "1", "--tls-cert",
                  cert("server.crt").string(), "--tls-key", cert("server.key").string(), "--tls-client-ca",
                  cert("ca.crt").string(), "--token-file", token.string()});
    const int port = wait_for_port(server);
    ASSERT_GT(port, 0) << server.output();
    auto client = [&](std::vector<std::string> extra) {
        std::vector<std::string> argv = {CATGS_CLIENT_BINARY, "--server", "127.0.0.1:" + std::to_string(port),
                                         "--retries", "0"};
        argv.insert(argv.end(), extra.begin(), extra.end());
        for (const char* a : {"stream", "--scene", "city", "--trajectory", "builtin:hover?frames=3", "--width", "160",
                              "--height", "90", "--rate", "0"})
            argv.push_back(a);
        auto child = std::make_unique<Child>(argv);
        const auto code = child->wait(std::chrono::seconds(30));
        return std::make_pair(code.value_or(-1), child->output());
    };
    const std::vector<std::string> tls = {"--tls-ca",   cert("ca.crt").string(),
                                          "--tls-cert", cert("client.crt").string(),
                                          "--tls-key",  cert("client.key").string()};
    std::vector<std::string> ok = tls;
    ok.insert(ok.end(), {"--token-file", token.string(), "--session-id", "viewer-7"});
    auto [code, out] = client(ok);
    EXPECT_EQ(code, 0) << out;
    EXPECT_NE(out.find("3 frames"), std::string::npos) << out;
    // The proxy affinity header reached the server (it logs it with the session).
    EXPECT_NE(server.output().find("(x-catgs-session viewer-7)"), std::string::npos) << server.output();
    // A header value must be printable ASCII: refused before connecting, exit 2.
    std::vector<std::string> bad_id = ok;
    bad_id.back() = "tab\there";
    std::tie(code, out) = client(bad_id);
    EXPECT_EQ(code, 2) << out;
    EXPECT_NE(out.find("--session-id: expected 1..128 printable ASCII characters"), std::string::npos) << out;
    // Without a client certificate: the handshake fails, UNAVAILABLE, exit 3.
    std::tie(code, out) = client({"--tls-ca", cert("ca.crt").string(), "--token-file", token.string()});
    EXPECT_EQ(code, 3) << out;
    EXPECT_NE(out.find("UNAVAILABLE"), std::string::npos) << out;
    // A wrong token: UNAUTHENTICATED, exit 5, and the server's message.
    std::vector<std::string> wrong = tls;
    wrong.insert(wrong.end(), {"--token-file", bad_token.string()});
    std::tie(code, out) = client(wrong);
    EXPECT_EQ(code, 5) << out;
    EXPECT_NE(out.find("UNAUTHENTICATED: authorization: wrong bearer token"), std::string::npos) << out;

    server.kill(SIGTERM);
    EXPECT_EQ(server.wait(std::chrono::seconds(10)).value_or(-1), 0) << server.output();
}

TEST_F(TlsTest, ClientCaWithoutServerCertificateIsABadFlag) {
    Child server({CATGS_SERVER_BINARY, "--address", "127.0.0.1:0", "--backend", "cpu", "--scene",
                  "builtin:city?gaussians=10000", "--tls-client-ca", cert("ca.crt").string()});
    EXPECT_EQ(server.wait(std::chrono::seconds(20)).value_or(-1), 2) << server.output();
    EXPECT_NE(server.output().find("--tls-client-ca needs --tls-cert and --tls-key"), std::string::npos)
        << server.output();
}

/// Scene paths: every way out of the root is refused with a message naming the source;
/// harmless spellings inside it are accepted.
class ScenePathTest : public SceneRootTest {
protected:
    void SetUp() override {
        make_root("path-test");
        fs::create_directories(root_ / "sub");
        fs::create_directories(base_ / "elsewhere");
        Scene small = load_scene("builtin:city?gaussians=10000&seed=4");
        write_ply(small, (root_ / "small.ply").string());
        write_ply(small, (base_ / "elsewhere" / "secret.ply").string());
        fs::create_symlink(base_ / "elsewhere", root_ / "linkdir");                 // a directory out of the root
        fs::create_symlink(base_ / "elsewhere" / "secret.ply", root_ / "out.ply");  // a file out of the root
        fs::create_symlink(root_ / "small.ply", root_ / "sub" / "in.ply");          // a link that stays inside
        start();
    }
};

TEST_F(ScenePathTest, WaysOutOfTheRootAreRefused) {
    struct Case {
        std::string source, message;
    };
    const std::vector<Case> refused = {
        {"../elsewhere/secret.ply", "source '../elsewhere/secret.ply': path leaves the scene root"},
        {"sub/../../elsewhere/secret.ply", "source 'sub/../../elsewhere/secret.ply': path leaves the scene root"},
        {"..", "source '..': path leaves the scene root"},
        {"linkdir/secret.ply", "source 'linkdir/secret.ply': path leaves the scene root"},
        {"out.ply", "source 'out.ply': path leaves the scene root"},
        {(base_ / "elsewhere" / "secret.ply").string(),
         "source '" + (base_ / "elsewhere" / "secret.ply").string() +
             "': expected a path relative to the scene root or a builtin: generator"},
        // Absolute paths are refused even when they point into the root.
        {(root_ / "small.ply").string(), "': expected a path relative to the scene root or a builtin: generator"},
        {"/etc/passwd", "source '/etc/passwd': expected a path relative to the scene root"},
        {"sub", "source 'sub': not a regular file"},
        {".", "source '.': not a regular file"},
        {"missing.ply", "source 'missing.ply': no such file under the scene root"},
        {std::string("small.ply\0../x", 14), "source: contains a NUL byte"},
    };
    for (const Case& c : refused) {
        SCOPED_TRACE(c.source);
        const grpc::Status status = load(c.source, "x");
        EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << status.error_message();
        EXPECT_NE(status.error_message().find(c.message), std::string::npos) << status.error_message();
    }
    // The messages never name the server's own directories for relative sources.
    const grpc::Status status = load("linkdir/secret.ply", "x");
    EXPECT_EQ(status.error_message().find(base_.string()), std::string::npos) << status.error_message();
    // Nothing was loaded.
    EXPECT_EQ(server_->core().scenes().list().size(), 1u);
}

// An unbundled SOG names its textures beside its meta.json: a link there that leaves the root
// is refused like a scene path that does, naming the texture but not the server's directories.
TEST_F(ScenePathTest, SceneFilesThatLinkOutOfTheRootAreRefused) {
    fs::create_directories(root_ / "sog");
    std::ofstream(root_ / "sog" / "meta.json") << R"({"version": 2, "count": 1,
               "means": {"mins": [0, 0, 0], "maxs": [1, 1, 1], "files": ["means_l.webp", "means_u.webp"]},
               "scales": {"codebook": [0], "files": ["scales.webp"]}, "quats": {"files": ["quats.webp"]},
               "sh0": {"codebook": [0], "files": ["sh0.webp"]}})";
    for (const char* name : {"means_u.webp", "scales.webp", "quats.webp", "sh0.webp"})
        std::ofstream(root_ / "sog" / name) << "not read: the link is refused first";
    std::ofstream(base_ / "elsewhere" / "means_l.webp") << "outside the root";
    fs::create_symlink(base_ / "elsewhere" / "means_l.webp", root_ / "sog" / "means_l.webp");

    const grpc::Status status = load("sog/meta.json", "x");
    EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << status.error_message();
    EXPECT_NE(status.error_message().find(
                  "source: sog/meta.json: texture 'means_l.webp' resolves outside the scene root (a link?)"),
              std::string::npos)
        << status.error_message();
    EXPECT_EQ(status.error_message().find(base_.string()), std::string::npos) << status.error_message();
    EXPECT_EQ(server_->core().scenes().list().size(), 1u);
}

TEST_F(ScenePathTest, SpellingsInsideTheRootAreAccepted) {
    for (const auto& [source, id] : std::vector<std::pair<std::string, std::string>>{{"small.ply", "a"},
                                                                                     {"./small.ply", "b"},
                                                                                     {"sub/../small.ply", "c"},
                                                                                     {"sub/in.ply", "d"},
                                                                                     {"sub//in.ply", "e"}}) {
        SCOPED_TRACE(source);
        const grpc::Status status = load(source, id);
        EXPECT_TRUE(status.ok()) << status.error_message();
    }
    EXPECT_EQ(server_->core().scenes().list().size(), 6u);
}

}  // namespace
}  // namespace catgs::test
