// The web endpoint of catgs-server (--web-address): one HTTP(S) port serving the browser
// viewer's static files, /healthz, unary calls as POST /api/<service>/<method>, and
// RenderService.Stream as a WebSocket at /ws/stream (docs/web.md: the contract).
//
// It is a gRPC client of the server's own services over the in-process channel: a WebSocket
// is one RenderService.Stream call whose bytes are forwarded unparsed both ways, so the
// stream session, its validation, limits, admission, backpressure and drain apply to browsers
// exactly as to gRPC clients. Boost.Beast (HTTP, WebSocket) and Asio (TLS through OpenSSL)
// run on their own small thread pool, never on gRPC's threads.
#pragma once

#include <grpcpp/grpcpp.h>

#include <chrono>
#include <cstddef>
#include <functional>
#include <memory>
#include <optional>
#include <string>

namespace catgs::server {

struct WebOptions {
    std::string address;  ///< host:port; port 0 picks a free one
    /// The viewer's static files; a missing folder makes GET / a page saying how to build it.
    std::string root;
    std::string tls_cert_file, tls_key_file;  ///< both given: HTTPS and WSS
    /// Connections open at once (HTTP and WebSocket); more are answered 503 and closed.
    int max_connections = 64;
    /// Asio threads: the endpoint only moves bytes, the rendering runs on the server's pools.
    int threads = 2;
    /// A whole HTTP request, a TLS handshake or a WebSocket opening or closing handshake must
    /// complete within this, and an idle keep-alive connection is closed after it: a
    /// slowloris client trickling bytes holds a connection no longer.
    std::chrono::milliseconds request_timeout{10000};
    /// A frame that the browser has not taken off the socket for this long ends its WebSocket
    /// (0: never). The session's stall watchdog (--stall-timeout-ms) has ended the call by
    /// then; this frees the socket, whose reader will never see a close frame.
    std::chrono::milliseconds frame_write_timeout{0};
};

class WebEndpoint {
public:
    /// `channel`: the server's in-process channel. `serving`: the server's health (false from
    /// the start of a drain), answered by /healthz.
    WebEndpoint(WebOptions options, std::shared_ptr<grpc::Channel> channel, std::function<bool()> serving);
    ~WebEndpoint();
    WebEndpoint(const WebEndpoint&) = delete;
    WebEndpoint& operator=(const WebEndpoint&) = delete;

    /// Binds and starts serving. Throws catgs::Error naming --web-address, --tls-cert or
    /// --tls-key when the port cannot be bound or a file cannot be read.
    void start();
    /// The bound port (useful with port 0).
    int port() const;
    /// What to open in a browser: http(s)://HOST:PORT/ (a wildcard host becomes localhost).
    std::string url() const;
    /// Closes the listener and every connection (running streams are cancelled), waits for
    /// their gRPC calls to end and stops the threads. Idempotent.
    void stop();
    /// Connections open now (a gauge, for tests and logs).
    std::size_t connections() const;

    class Impl;

private:
    std::unique_ptr<Impl> impl_;
};

namespace web {

/// WebSocket close code for a stream that ended with `code`: 1000 for OK, else 4000 + code.
int close_code_for(grpc::StatusCode code);
/// "<CODE_NAME>: <message>", cut at a UTF-8 character boundary to fit `max_bytes` (a close
/// frame's reason holds 123 bytes).
std::string status_text(const grpc::Status& status, std::size_t max_bytes = std::string::npos);
/// The gRPC status code's name, e.g. "INVALID_ARGUMENT".
const char* code_name(grpc::StatusCode code);
/// The HTTP status a unary call's gRPC status is answered with.
int http_status_for(grpc::StatusCode code);

/// The file under `root` that a request target (path and query, as sent) names, or an error:
/// the query is dropped, %XX escapes decoded, "/" means index.html; "." and ".." segments,
/// hidden files, NUL, backslashes and anything whose real path (symlinks resolved) leaves
/// `root` are refused. `root` must be canonical.
struct StaticPath {
    std::string path;   ///< the file's real path, when found
    std::string error;  ///< else why not (for the 404/400 body)
    int http_status = 200;
};
StaticPath resolve_static_path(const std::string& root, const std::string& target);
/// The content type by file extension (application/octet-stream when unknown).
std::string content_type_for(const std::string& path);
/// The value of query parameter `name` in a request target, %-decoded; nullopt when absent.
std::optional<std::string> query_parameter(const std::string& target, const std::string& name);

}  // namespace web
}  // namespace catgs::server
