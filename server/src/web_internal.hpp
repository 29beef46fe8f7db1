// What the web endpoint's files share (server/src only): the Beast/Asio types, the limits and
// their reasons, the endpoint's state (WebEndpoint::Impl) and its connection registry.
#pragma once

#include <boost/asio/dispatch.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/ssl.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/asio/strand.hpp>
#include <boost/asio/write.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/ssl.hpp>
#include <grpcpp/generic/generic_stub.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <condition_variable>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "catgs/common/net_config.hpp"
#include "catgs/server/web_endpoint.hpp"

namespace catgs::server {

namespace beast = boost::beast;
namespace http = beast::http;
namespace asio = boost::asio;
namespace ssl = asio::ssl;
using tcp = asio::ip::tcp;
using PlainStream = beast::tcp_stream;
using TlsStream = beast::ssl_stream<beast::tcp_stream>;
using HttpRequest = http::request<http::string_body>;

namespace web {

/// A request line plus headers beyond this is refused (431): browsers send 1-2 KB, and the
/// parser buffers the whole header.
inline constexpr std::size_t kHeaderLimit = 16 * 1024;
/// Request bodies (unary calls) and WebSocket messages: the same cap as a gRPC request, so a
/// browser can send nothing a gRPC client could not.
inline constexpr std::size_t kMaxRequestBytes = net::kMaxRequestMessageBytes;
/// A WebSocket from which nothing (not even a pong to our pings, sent at half this) arrives
/// for this long is closed: the browser is gone or does not read. Browsers answer pings
/// without the page's help, so a live but idle viewer is never cut.
inline constexpr std::chrono::seconds kWebSocketIdleTimeout{60};
/// Unary calls: a Render of a 4K PNG on the CPU takes seconds; this bounds a stuck one.
inline constexpr std::chrono::seconds kUnaryDeadline{60};
/// On stop(): how long connections already closing (WebSockets sending their close frame)
/// get before every connection left is closed hard.
inline constexpr std::chrono::milliseconds kStopGrace{1000};
/// On stop(): how long the cancelled calls get to deliver their last callback (gRPC does so
/// within milliseconds; this only bounds a shutdown that would otherwise hang).
inline constexpr std::chrono::seconds kCallsEndWait{10};
/// A close frame's reason holds 123 bytes (RFC 6455 5.5: 125-byte control payload, 2 for the
/// code).
inline constexpr std::size_t kCloseReasonBytes = 123;
/// Read WebSocket messages in pieces of this size, so the size cap is checked as bytes arrive.
inline constexpr std::size_t kReadChunkBytes = 64 * 1024;

/// An open connection, as the endpoint's registry sees it.
class Connection {
public:
    virtual ~Connection() = default;
    /// Called from any thread on stop(); `hard`: close the socket now, even mid-close.
    virtual void close_now(bool hard) = 0;
};

/// Printable ASCII only: what gRPC admits in a metadata value.
bool is_metadata_safe(const std::string& value);

}  // namespace web

class WebEndpoint::Impl {
    // The registry first: members are destroyed in reverse order, and destroying `io` runs the
    // destructors of handlers never run, whose connections then unregister here.
    mutable std::mutex mutex_;
    std::condition_variable changed_;
    std::map<std::uint64_t, std::weak_ptr<web::Connection>> connections_;
    std::uint64_t next_id_ = 1;
    std::size_t calls_ = 0;
    bool stopping_ = false, started_ = false, leaked_ = false;

public:
    Impl(WebOptions options, std::shared_ptr<grpc::Channel> channel, std::function<bool()> serving);

    const WebOptions options;
    std::shared_ptr<grpc::Channel> channel;
    grpc::GenericStub stub;
    std::function<bool()> serving;
    std::string root;  ///< canonical; empty when the folder does not exist
    asio::io_context io;
    std::optional<ssl::context> tls;
    tcp::acceptor acceptor;  ///< on its own strand: stop() closes it from another thread
    tcp::endpoint bound;     ///< set by start()
    std::vector<std::thread> threads;

    /// Registry: every connection registers (weakly) until it is destroyed, every gRPC call
    /// counts until its last callback, so that stop() can wait for both.
    std::uint64_t add_connection(const std::shared_ptr<web::Connection>& connection);
    void remove_connection(std::uint64_t id);
    std::size_t connection_count() const;
    void call_started();
    void call_ended();

    void start();
    void stop();
    bool stopping() const;
    /// A call outlived stop()'s wait: the state must not be freed.
    bool leaked() const { return leaked_; }

private:
    void accept();
    void on_accept(tcp::socket socket);
};

/// Serves HTTP (after a TLS handshake when the endpoint has TLS) on an accepted socket
/// (web_http.cpp).
void start_http(WebEndpoint::Impl& endpoint, tcp::socket socket);
/// Hands an upgraded HTTP connection over to a WebSocket bridge (web_socket.cpp).
void start_websocket(WebEndpoint::Impl& endpoint, PlainStream stream, HttpRequest request, std::string peer);
void start_websocket(WebEndpoint::Impl& endpoint, TlsStream stream, HttpRequest request, std::string peer);

/// The bearer token a request carries: "Authorization: Bearer X" or ?token=X; empty if none.
std::string request_token(const HttpRequest& request);
/// Client metadata for a call made on a browser's behalf: its token, its address (logged by
/// the session) and its affinity key (?session=).
bool add_call_metadata(grpc::ClientContext* context, const HttpRequest& request, const std::string& peer,
                       grpc::Status* refused);
/// The bytes of a message the bridge got from the in-process call, as one string (empty if
/// the buffer cannot be read).
std::string byte_buffer_to_string(const grpc::ByteBuffer& buffer);

}  // namespace catgs::server
