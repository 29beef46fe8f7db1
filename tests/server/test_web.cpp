// The web endpoint against an in-process server (CPU backend, small built-in city): the
// WebSocket bridge answers exactly as RenderService.Stream does over gRPC (frames, error
// frames, the status as close code and reason), unary calls over HTTP, static files,
// /healthz, tokens, TLS, the drain, and hostile clients. Clients are Boost.Beast, synchronous,
// with socket timeouts so that a hang fails instead of blocking.
#include <sys/socket.h>

#include <boost/asio/connect.hpp>
#include <boost/asio/read.hpp>
#include <boost/asio/write.hpp>
#include <boost/asio/ssl.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/ssl.hpp>
#include <boost/beast/websocket.hpp>

#include "catgs/server/web_endpoint.hpp"
#include "server_test_util.hpp"

namespace catgs::test {
namespace {

namespace fs = std::filesystem;
namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
namespace asio = boost::asio;
using tcp = asio::ip::tcp;
using Response = http::response<http::string_body>;

/// Any answer the tests wait for arrives well within this; a hang fails the test.
constexpr int kSocketTimeoutS = 20 * kTimingSlack;

void set_socket_timeout(tcp::socket& socket, int seconds) {
    timeval tv{seconds, 0};
    setsockopt(socket.native_handle(), SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    setsockopt(socket.native_handle(), SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
}

tcp::socket connect_to(asio::io_context& io, int port) {
    tcp::socket socket(io);
    socket.connect({asio::ip::make_address("127.0.0.1"), static_cast<unsigned short>(port)});
    set_socket_timeout(socket, kSocketTimeoutS);
    return socket;
}

Response http_call(int port, http::verb method, const std::string& target, const std::string& body = "",
                   const std::vector<std::pair<std::string, std::string>>& headers = {}) {
    asio::io_context io;
    tcp::socket socket = connect_to(io, port);
    http::request<http::string_body> request{method, target, 11};
    request.set(http::field::host, "127.0.0.1");
    for (const auto& [name, value] : headers) request.set(name, value);
    request.body() = body;
    request.prepare_payload();
    beast::error_code ec;
    http::write(socket, request, ec);  // a refusal may come before the whole request is sent
    beast::flat_buffer buffer;
    http::response_parser<http::string_body> parser;
    parser.body_limit(64 * 1024 * 1024);
    http::read(socket, buffer, parser);
    return parser.release();
}

template <typename Message>
Response api_call(int port, const std::string& method, const Message& request, const std::string& query = "",
                  std::vector<std::pair<std::string, std::string>> headers = {}) {
    headers.emplace_back("content-type", "application/x-protobuf");
    return http_call(port, http::verb::post, "/api/catgs.v1." + method + query, request.SerializeAsString(), headers);
}

/// A browser's side of /ws/stream: binary StreamRequests up, Frames down.
struct WsClient {
    asio::io_context io;
    websocket::stream<tcp::socket> ws{io};

    explicit WsClient(int port, const std::string& target = "/ws/stream") {
        ws.next_layer() = connect_to(io, port);
        ws.read_message_max(128 * 1024 * 1024);
        ws.handshake("127.0.0.1", target);
        ws.binary(true);
    }
    void send(const v1::StreamRequest& request) { ws.write(asio::buffer(request.SerializeAsString())); }
    void send_bytes(const std::string& bytes, bool binary = true) {
        ws.binary(binary);
        ws.write(asio::buffer(bytes));
        ws.binary(true);
    }
    /// The next frame; false when the server closed the socket (see close_code()).
    bool read(v1::Frame* frame) {
        beast::flat_buffer buffer;
        beast::error_code ec;
        ws.read(buffer, ec);
        if (ec) return false;
        EXPECT_TRUE(ws.got_binary());
        EXPECT_TRUE(frame->ParseFromString(beast::buffers_to_string(buffer.data())));
        return true;
    }
    /// Reads until the server closes; returns how many frames came first.
    int read_until_closed() {
        int frames = 0;
        v1::Frame frame;
        while (read(&frame)) ++frames;
        return frames;
    }
    int close_code() const { return static_cast<int>(ws.reason().code); }
    std::string close_reason() const { return std::string(ws.reason().reason.c_str()); }
};

class WebTest : public ::testing::Test {
protected:
    void SetUp() override {
        root_ = fs::path(CATGS_TEST_TMP) / ("web-root-" + std::to_string(getpid()));
        fs::remove_all(root_);
        fs::create_directories(root_);
        std::ofstream(root_ / "index.html") << "<!doctype html><title>catgs viewer</title>";
        std::ofstream(root_ / "app.js") << "console.log('viewer')";
    }
    void TearDown() override {
        server_.reset();
        std::error_code ec;
        fs::remove_all(root_, ec);
    }
    server::ServerOptions web_options() {
        server::ServerOptions o = test_options();
        o.web_address = "127.0.0.1:0";
        o.web_root = root_.string();
        return o;
    }
    void start(server::ServerOptions o) { server_ = start_server(std::move(o)); }
    int web_port() const { return server_->web_port(); }

    fs::path root_;
    std::unique_ptr<server::Server> server_;
};

TEST_F(WebTest, StreamOverWebSocketSendsFramesAndTakesAcknowledgements) {
    start(web_options());
    EXPECT_EQ(server_->web_url(), "http://127.0.0.1:" + std::to_string(web_port()) + "/");
    WsClient client(web_port());
    v1::SessionConfig config = session_config(v1::ENCODING_JPEG, 80);
    config.set_max_unacked_frames(1);
    client.send(open_message(config));
    const auto path = uav_path(4);
    std::uint64_t ack = 0;
    for (std::uint64_t seq = 1; seq <= 4; ++seq) {
        client.send(frame_message(frame_request(seq, path[seq - 1], ack)));
        v1::Frame frame;
        ASSERT_TRUE(client.read(&frame)) << client.close_code() << " " << client.close_reason();
        EXPECT_EQ(frame.sequence(), seq);
        EXPECT_EQ(frame.width(), static_cast<unsigned>(kWidth));
        EXPECT_FALSE(frame.has_error());
        const ImageRGB8 image = decode_frame(frame);
        EXPECT_EQ(image.width, kWidth);
        // With one unacknowledged frame allowed, the next frame comes only after this ack.
        ack = frame.sequence();
    }
    client.ws.close(websocket::close_code::normal);
    EXPECT_TRUE(eventually([&] { return server_->stats().streams_open == 0; }));
}

TEST_F(WebTest, BadOpenClosesWithTheStatusGrpcGives) {
    start(web_options());
    v1::SessionConfig config = session_config(v1::ENCODING_JPEG);
    config.set_width(0);
    StreamClient grpc_client(channel_to(server_->port()));
    ASSERT_TRUE(grpc_client.open(config));
    const grpc::Status grpc_status = grpc_client.finish();
    ASSERT_EQ(grpc_status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);

    WsClient client(web_port());
    client.send(open_message(config));
    EXPECT_EQ(client.read_until_closed(), 0);
    EXPECT_EQ(client.close_code(), 4003);
    EXPECT_EQ(client.close_reason(), "INVALID_ARGUMENT: " + grpc_status.error_message());
    EXPECT_NE(client.close_reason().find("open.width: 0 is outside"), std::string::npos);
}

TEST_F(WebTest, BadFrameRequestGetsAnErrorFrameAndTheSessionGoesOn) {
    start(web_options());
    WsClient client(web_port());
    client.send(open_message(session_config(v1::ENCODING_JPEG)));
    v1::FrameRequest bad = frame_request(1, uav_path(2)[0], 0);
    bad.mutable_pose()->mutable_position()->set_y(std::numeric_limits<double>::quiet_NaN());
    client.send(frame_message(bad));
    v1::Frame frame;
    ASSERT_TRUE(client.read(&frame));
    EXPECT_EQ(frame.sequence(), 1u);
    EXPECT_EQ(frame.error().code(), static_cast<int>(grpc::StatusCode::INVALID_ARGUMENT));
    EXPECT_NE(frame.error().message().find("frame.pose.position: not finite"), std::string::npos)
        << frame.error().message();
    client.send(frame_message(frame_request(2, uav_path(2)[1], 1)));
    ASSERT_TRUE(client.read(&frame));
    EXPECT_EQ(frame.sequence(), 2u);
    EXPECT_FALSE(frame.has_error());
}

TEST_F(WebTest, MalformedTextAndOversizeMessagesCloseWithAReason) {
    start(web_options());
    {
        WsClient client(web_port());
        const std::string garbage = "\xff\xff\xff\xff not protobuf";
        client.send_bytes(garbage);
        EXPECT_EQ(client.read_until_closed(), 0);
        EXPECT_EQ(client.close_code(), 4003);
        EXPECT_EQ(client.close_reason(), "INVALID_ARGUMENT: request: " + std::to_string(garbage.size()) +
                                             " bytes that are not a valid catgs.v1.StreamRequest message "
                                             "(malformed protobuf)");
    }
    {
        WsClient client(web_port());
        client.send_bytes("{\"open\": {}}", /*binary=*/false);
        EXPECT_EQ(client.read_until_closed(), 0);
        EXPECT_EQ(client.close_code(), 1003);
        EXPECT_NE(client.close_reason().find("text message"), std::string::npos) << client.close_reason();
    }
    {
        WsClient client(web_port());
        client.send_bytes(std::string(net::kMaxRequestMessageBytes + 1, '\x0a'));
        EXPECT_EQ(client.read_until_closed(), 0);
        EXPECT_EQ(client.close_code(), 1009);
        EXPECT_NE(client.close_reason().find("1048576 bytes"), std::string::npos) << client.close_reason();
    }
    EXPECT_TRUE(eventually([&] { return server_->stats().streams_open == 0; }));
}

TEST_F(WebTest, TokenIsCheckedOnUnaryCallsAndBeforeAnyFrame) {
    server::ServerOptions o = web_options();
    o.bearer_token = "s3cret";
    start(o);
    const Response missing = api_call(web_port(), "SceneService/ListScenes", v1::ListScenesRequest());
    EXPECT_EQ(missing.result_int(), 401);
    EXPECT_EQ(missing["grpc-status"], "16");
    EXPECT_EQ(missing.body(), "UNAUTHENTICATED: authorization: missing metadata 'authorization: Bearer <token>'\n");
    const Response header = api_call(web_port(), "SceneService/ListScenes", v1::ListScenesRequest(), "",
                                     {{"authorization", "Bearer s3cret"}});
    EXPECT_EQ(header.result_int(), 200);
    const Response query = api_call(web_port(), "SceneService/ListScenes", v1::ListScenesRequest(), "?token=s3cret");
    EXPECT_EQ(query.result_int(), 200);
    // Static files stay open: the page itself asks for the token.
    EXPECT_EQ(http_call(web_port(), http::verb::get, "/").result_int(), 200);

    WsClient wrong(web_port(), "/ws/stream?token=nope");
    wrong.send(open_message(session_config(v1::ENCODING_JPEG)));
    wrong.send(frame_message(frame_request(1, uav_path(2)[0], 0)));
    EXPECT_EQ(wrong.read_until_closed(), 0);
    EXPECT_EQ(wrong.close_code(), 4016);
    EXPECT_EQ(wrong.close_reason(), "UNAUTHENTICATED: authorization: wrong bearer token");

    WsClient right(web_port(), "/ws/stream?token=s3cret&session=viewer-1");
    right.send(open_message(session_config(v1::ENCODING_JPEG)));
    right.send(frame_message(frame_request(1, uav_path(2)[0], 0)));
    v1::Frame frame;
    EXPECT_TRUE(right.read(&frame));
}

TEST_F(WebTest, UnaryScenesCallsOverHttp) {
    start(web_options());
    const Response list = api_call(web_port(), "SceneService/ListScenes", v1::ListScenesRequest());
    ASSERT_EQ(list.result_int(), 200) << list.body();
    EXPECT_EQ(list[http::field::content_type], "application/x-protobuf");
    v1::ListScenesResponse scenes;
    ASSERT_TRUE(scenes.ParseFromString(list.body()));
    ASSERT_EQ(scenes.scenes_size(), 1);
    EXPECT_EQ(scenes.scenes(0).scene_id(), "city");
    EXPECT_GT(scenes.scenes(0).bounds().max().x(), scenes.scenes(0).bounds().min().x());

    v1::GetSceneRequest get;
    get.set_scene_id("city");
    const Response found = api_call(web_port(), "SceneService/GetScene", get);
    v1::SceneInfo info;
    ASSERT_EQ(found.result_int(), 200);
    ASSERT_TRUE(info.ParseFromString(found.body()));
    EXPECT_EQ(info.gaussian_count(), scenes.scenes(0).gaussian_count());

    // The same message as over gRPC, with the code in the HTTP status and in grpc-status.
    get.set_scene_id("nowhere");
    grpc::ClientContext context;
    v1::SceneInfo ignored;
    const grpc::Status grpc_status =
        v1::SceneService::NewStub(channel_to(server_->port()))->GetScene(&context, get, &ignored);
    const Response missing = api_call(web_port(), "SceneService/GetScene", get);
    EXPECT_EQ(missing.result_int(), 404);
    EXPECT_EQ(missing["grpc-status"], "5");
    EXPECT_EQ(missing.body(), "NOT_FOUND: " + grpc_status.error_message() + "\n");

    const Response garbage = http_call(web_port(), http::verb::post, "/api/catgs.v1.SceneService/GetScene", "\xff\xff",
                                       {{"content-type", "application/x-protobuf"}});
    EXPECT_EQ(garbage.result_int(), 400);
    EXPECT_NE(garbage.body().find("not a valid catgs.v1.GetSceneRequest"), std::string::npos) << garbage.body();
    const Response admin = api_call(web_port(), "SceneService/UnloadScene", get);
    EXPECT_EQ(admin.result_int(), 500);
    EXPECT_EQ(admin["grpc-status"], "12");
    const Response text = http_call(web_port(), http::verb::post, "/api/catgs.v1.SceneService/ListScenes", "",
                                    {{"content-type", "text/plain"}});
    EXPECT_EQ(text.result_int(), 400);
    EXPECT_NE(text.body().find("application/x-protobuf"), std::string::npos);
    const Response big =
        http_call(web_port(), http::verb::post, "/api/catgs.v1.SceneService/ListScenes",
                  std::string(net::kMaxRequestMessageBytes + 1, 'x'), {{"content-type", "application/x-protobuf"}});
    EXPECT_EQ(big.result_int(), 413);
}

TEST_F(WebTest, StaticFilesHealthAndRefusals) {
    start(web_options());
    const Response index = http_call(web_port(), http::verb::get, "/");
    EXPECT_EQ(index.result_int(), 200);
    EXPECT_EQ(index[http::field::content_type], "text/html; charset=utf-8");
    EXPECT_EQ(index.body(), "<!doctype html><title>catgs viewer</title>");
    const std::string etag(index[http::field::etag]);
    EXPECT_EQ(http_call(web_port(), http::verb::get, "/index.html", "", {{"if-none-match", etag}}).result_int(), 304);
    const Response js = http_call(web_port(), http::verb::get, "/app.js?v=1");
    EXPECT_EQ(js[http::field::content_type], "text/javascript; charset=utf-8");
    EXPECT_EQ(js[http::field::cache_control], "no-cache");
    for (const char* target : {"/../../etc/passwd", "/%2e%2e/%2e%2e/etc/passwd", "//etc/passwd", "/etc/passwd"}) {
        SCOPED_TRACE(target);
        const Response r = http_call(web_port(), http::verb::get, target);
        EXPECT_TRUE(r.result_int() == 400 || r.result_int() == 404) << r.result_int();
        EXPECT_EQ(r.body().find("root:"), std::string::npos);
    }
    EXPECT_EQ(http_call(web_port(), http::verb::delete_, "/index.html").result_int(), 405);
    EXPECT_EQ(http_call(web_port(), http::verb::get, "/ws/stream").result_int(), 426);
    const Response huge = http_call(web_port(), http::verb::get, "/", "", {{"x-filler", std::string(20000, 'a')}});
    EXPECT_EQ(huge.result_int(), 431);

    const Response healthy = http_call(web_port(), http::verb::get, "/healthz");
    EXPECT_EQ(healthy.result_int(), 200);
    EXPECT_EQ(healthy.body(), "SERVING\n");
    server_->begin_shutdown();
    const Response draining = http_call(web_port(), http::verb::get, "/healthz");
    EXPECT_EQ(draining.result_int(), 503);
    EXPECT_EQ(draining.body(), "NOT_SERVING\n");
}

TEST_F(WebTest, MissingWebRootSaysTheViewerIsNotBuilt) {
    server::ServerOptions o = web_options();
    o.web_root = (root_ / "no-such-dist").string();
    start(o);
    const Response r = http_call(web_port(), http::verb::get, "/");
    EXPECT_EQ(r.result_int(), 404);
    EXPECT_NE(r.body().find("web viewer was not built"), std::string::npos) << r.body();
    EXPECT_EQ(http_call(web_port(), http::verb::get, "/healthz").result_int(), 200);
}

TEST_F(WebTest, DrainClosesWebSocketsWithTheShutdownStatus) {
    server::ServerOptions o = web_options();
    o.drain_ms = 300;
    start(o);
    WsClient running(web_port());
    running.send(open_message(session_config(v1::ENCODING_JPEG)));
    running.send(frame_message(frame_request(1, uav_path(2)[0], 0)));
    v1::Frame frame;
    ASSERT_TRUE(running.read(&frame));
    server_->begin_shutdown();
    running.read_until_closed();
    EXPECT_EQ(running.close_code(), 4014);
    const std::string expected = server::web::status_text(server::shutting_down_status(), 123);
    EXPECT_EQ(running.close_reason(), expected);
    EXPECT_EQ(running.close_reason().rfind("UNAVAILABLE: server is shutting down", 0), 0u);

    WsClient late(web_port());
    late.send(open_message(session_config(v1::ENCODING_JPEG)));
    EXPECT_EQ(late.read_until_closed(), 0);
    EXPECT_EQ(late.close_code(), 4014);
    EXPECT_EQ(late.close_reason(), expected);
    // Stopping with a WebSocket open (it never sent its opening message) does not hang or crash.
    WsClient idle(web_port());
    server_->shutdown(std::chrono::milliseconds(500));
    idle.read_until_closed();
}

TEST_F(WebTest, TlsServesHttpsAndWss) {
    const fs::path certs = root_ / "certs";
    const std::string command = "bash '" CATGS_CERT_SCRIPT "' '" + certs.string() + "' > /dev/null";
    ASSERT_EQ(std::system(command.c_str()), 0) << command;
    server::ServerOptions o = web_options();
    o.tls_cert_file = (certs / "server.crt").string();
    o.tls_key_file = (certs / "server.key").string();
    start(o);
    EXPECT_EQ(server_->web_url().rfind("https://", 0), 0u);
    asio::io_context io;
    asio::ssl::context tls(asio::ssl::context::tls_client);
    tls.load_verify_file((certs / "ca.crt").string());
    tls.set_verify_mode(asio::ssl::verify_peer);
    websocket::stream<beast::ssl_stream<tcp::socket>> ws(io, tls);
    beast::get_lowest_layer(ws) = connect_to(io, web_port());
    ws.next_layer().handshake(asio::ssl::stream_base::client);
    ws.handshake("localhost", "/ws/stream");
    ws.binary(true);
    ws.write(asio::buffer(open_message(session_config(v1::ENCODING_JPEG)).SerializeAsString()));
    ws.write(asio::buffer(frame_message(frame_request(1, uav_path(2)[0], 0)).SerializeAsString()));
    beast::flat_buffer buffer;
    ws.read(buffer);
    v1::Frame frame;
    ASSERT_TRUE(frame.ParseFromString(beast::buffers_to_string(buffer.data())));
    EXPECT_EQ(frame.sequence(), 1u);
    // Plaintext to the TLS port gets nothing served.
    asio::io_context plain_io;
    tcp::socket plain = connect_to(plain_io, web_port());
    set_socket_timeout(plain, 5 * kTimingSlack);
    beast::error_code ec;
    asio::write(plain, asio::buffer(std::string("GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n")), ec);
    char reply[64];
    const std::size_t n = plain.read_some(asio::buffer(reply), ec);
    EXPECT_EQ(std::string(reply, n).find("SERVING"), std::string::npos);
}

/// A browser that sends poses, acknowledges blindly and never reads: its socket fills, the
/// bridge stops taking frames from the call, the session's stall watchdog ends the stream
/// (counted as a stall), and a second later the endpoint drops the socket. The session held
/// one frame in flight and at most one waiting throughout.
TEST_F(WebTest, BrowserThatNeverReadsIsStalledOutAndHoldsNothing) {
    server::ServerOptions o = web_options();
    o.limits.stall_timeout_ms = 1000;
    o.limits.max_width = 1280;
    o.limits.max_height = 720;
    start(o);
    // 2.7 MB raw frames against a 64 KB receive window fill the socket after a frame or two.
    asio::io_context io;
    websocket::stream<tcp::socket> reader_less(io);
    reader_less.next_layer().open(tcp::v4());
    reader_less.next_layer().set_option(asio::socket_base::receive_buffer_size(64 * 1024));
    reader_less.next_layer().connect({asio::ip::make_address("127.0.0.1"), static_cast<unsigned short>(web_port())});
    set_socket_timeout(reader_less.next_layer(), kSocketTimeoutS);
    reader_less.handshake("127.0.0.1", "/ws/stream");
    reader_less.binary(true);
    v1::SessionConfig big = session_config(v1::ENCODING_RAW_RGB8);
    big.set_width(1280);
    big.set_height(720);
    reader_less.write(asio::buffer(open_message(big).SerializeAsString()));
    // Poses keep coming (every 50 ms, each acknowledging itself), so frames keep coming until
    // the socket is full; the loop ends when the server drops the connection.
    std::atomic<bool> stop_sending{false};
    std::thread sender([&] {
        const auto path = uav_path(16, 1280, 720);
        beast::error_code write_error;
        for (std::uint64_t seq = 1; !stop_sending && !write_error; ++seq) {
            const std::string request = frame_message(frame_request(seq, path[seq % 16], seq)).SerializeAsString();
            reader_less.write(asio::buffer(request), write_error);
            std::this_thread::sleep_for(std::chrono::milliseconds(50));
        }
    });
    EXPECT_TRUE(eventually([&] { return server_->stats().streams_stalled >= 1; },
                           std::chrono::milliseconds(30000 * kTimingSlack)));
    EXPECT_TRUE(eventually([&] { return server_->stats().streams_open == 0; }));
    stop_sending = true;
    sender.join();
    EXPECT_LE(server_->stats().peak_session_buffered, 2);
    // The endpoint still serves others.
    EXPECT_EQ(http_call(web_port(), http::verb::get, "/healthz").body(), "SERVING\n");
}

/// Clients that never finish a request or open more connections than allowed are cut off
/// within the endpoint's timeouts, and nothing is held afterwards.
TEST_F(WebTest, SlowAndGreedyClientsAreCutOff) {
    start(test_options());
    server::WebOptions w;
    w.address = "127.0.0.1:0";
    w.root = root_.string();
    w.max_connections = 4;
    w.request_timeout = std::chrono::milliseconds(500 * kTimingSlack);
    // The same endpoint over a TCP channel to the server: its timeouts are the test's to choose.
    server::WebEndpoint endpoint(w, channel_to(server_->port()), [] { return true; });
    endpoint.start();
    const int port = endpoint.port();

    // Half a request line, and a slowloris trickling header lines.
    asio::io_context raw_io;
    tcp::socket half = connect_to(raw_io, port);
    asio::write(half, asio::buffer(std::string("GET /index.ht")));
    tcp::socket slow = connect_to(raw_io, port);
    asio::write(slow, asio::buffer(std::string("GET / HTTP/1.1\r\n")));
    beast::error_code ec;
    const auto slow_start = std::chrono::steady_clock::now();
    for (int i = 0; i < 40 && !ec; ++i) {
        asio::write(slow, asio::buffer(std::string("X-Slow: 1\r\n")), ec);
        std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    EXPECT_TRUE(ec) << "a request trickled for 4 s was not cut off";
    EXPECT_LT(std::chrono::steady_clock::now() - slow_start, std::chrono::seconds(4 * kTimingSlack));
    char byte;
    half.read_some(asio::buffer(&byte, 1), ec);
    EXPECT_EQ(ec, asio::error::eof);
    EXPECT_TRUE(eventually([&] { return endpoint.connections() == 0; }));

    // Over the connection cap: 503 at once, without parsing; then slots free up again.
    std::vector<tcp::socket> held;
    for (int i = 0; i < w.max_connections; ++i) held.push_back(connect_to(raw_io, port));
    EXPECT_TRUE(eventually([&] { return endpoint.connections() == static_cast<std::size_t>(w.max_connections); }));
    tcp::socket over = connect_to(raw_io, port);
    std::string reply(256, '\0');
    reply.resize(asio::read(over, asio::buffer(reply), ec));
    EXPECT_EQ(reply.rfind("HTTP/1.1 503", 0), 0u) << reply;
    held.clear();
    EXPECT_TRUE(eventually([&] { return endpoint.connections() == 0; }));
    EXPECT_EQ(http_call(port, http::verb::get, "/healthz").body(), "SERVING\n");
    endpoint.stop();
}

/// Pose-to-frame latency through the WebSocket bridge against gRPC on the same server and
/// scene: one pose at a time, the next sent when its frame arrived. Prints the numbers (the
/// web endpoint's cost is the difference); asserts only that every frame came back.
TEST_F(WebTest, PoseToFrameLatencyWebSocketAgainstGrpc) {
    start(web_options());
    constexpr int kPoses = 40, kBenchWidth = 320, kBenchHeight = 180;
    v1::SessionConfig config = session_config(v1::ENCODING_JPEG, 80);
    config.set_width(kBenchWidth);
    config.set_height(kBenchHeight);
    const auto path = uav_path(kPoses, kBenchWidth, kBenchHeight);
    using Ms = std::chrono::duration<double, std::milli>;
    auto summary = [](std::vector<double> ms) {
        std::sort(ms.begin(), ms.end());
        char text[96];
        std::snprintf(text, sizeof text, "median %.2f ms, p90 %.2f ms, min %.2f ms", ms[ms.size() / 2],
                      ms[ms.size() * 9 / 10], ms[0]);
        return std::string(text);
    };
    std::vector<double> grpc_ms, ws_ms;
    {
        StreamClient client(channel_to(server_->port()));
        ASSERT_TRUE(client.open(config));
        v1::Frame frame;
        for (int i = 0; i < kPoses; ++i) {
            const auto sent = std::chrono::steady_clock::now();
            ASSERT_TRUE(client.send(frame_request(i + 1, path[i], i)));
            ASSERT_TRUE(client.stream->Read(&frame));
            grpc_ms.push_back(Ms(std::chrono::steady_clock::now() - sent).count());
        }
        EXPECT_TRUE(client.close().ok());
    }
    {
        WsClient client(web_port());
        client.send(open_message(config));
        v1::Frame frame;
        for (int i = 0; i < kPoses; ++i) {
            const auto sent = std::chrono::steady_clock::now();
            client.send(frame_message(frame_request(i + 1, path[i], i)));
            ASSERT_TRUE(client.read(&frame));
            ws_ms.push_back(Ms(std::chrono::steady_clock::now() - sent).count());
        }
    }
    std::printf("pose-to-frame, %d poses, %dx%d JPEG, CPU backend:\n  gRPC      %s\n  WebSocket %s\n", kPoses,
                kBenchWidth, kBenchHeight, summary(grpc_ms).c_str(), summary(ws_ms).c_str());
    RecordProperty("grpc_median_ms", summary(grpc_ms));
    RecordProperty("websocket_median_ms", summary(ws_ms));
}

}  // namespace
}  // namespace catgs::test
