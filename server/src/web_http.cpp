// One HTTP(S) connection of the web endpoint: bounded request reading, then routing to
// /healthz, a unary call (POST /api/<service>/<method>, forwarded as bytes to the server's own
// gRPC service), a static file of the viewer, or the WebSocket upgrade (web_socket.cpp).
#include <boost/beast/websocket/rfc6455.hpp>
#include <spdlog/spdlog.h>

#include <array>
#include <filesystem>
#include <system_error>
#include <type_traits>

#include "web_internal.hpp"

namespace catgs::server {
namespace {

/// The unary methods a browser may call: what the viewer needs (scenes, their bounds, a
/// still). Loading and unloading scenes stay on gRPC, for operators.
constexpr std::array<const char*, 3> kWebUnaryMethods = {
    "/catgs.v1.SceneService/ListScenes", "/catgs.v1.SceneService/GetScene", "/catgs.v1.RenderService/Render"};
constexpr const char* kProtobufType = "application/x-protobuf";
constexpr const char* kServerName = "catgs-server";
/// How long a connection being closed after an error keeps draining what the client sends.
constexpr std::chrono::seconds kLinger{2};
/// The longest affinity key or forwarded address passed on into a session's logs.
constexpr std::size_t kMaxLoggedHeader = 128;

const char* const kViewerNotBuilt =
    "<!doctype html><meta charset=utf-8><title>catgs: viewer not built</title>"
    "<h1>The web viewer was not built</h1>"
    "<p>catgs-server serves the viewer's files from its <code>--web-root</code> folder, which does not exist. "
    "Build the viewer (client/web, see docs/web.md: <code>cmake --build build</code> after "
    "<code>bash client/web/install-deps.sh</code>) or point <code>--web-root</code> at a built copy.</p>"
    "<p>The WebSocket endpoint <code>/ws/stream</code>, <code>/api/</code> and <code>/healthz</code> work "
    "without it.</p>\n";

/// gRPC's own encoding of grpc-message (PROTOCOL-HTTP2.md): %XX for bytes outside printable
/// ASCII and for '%', so any message fits a header value.
std::string percent_encode_header(const std::string& text) {
    static const char kHex[] = "0123456789ABCDEF";
    std::string out;
    for (unsigned char c : text) {
        if (c >= 0x20 && c <= 0x7e && c != '%') {
            out.push_back(static_cast<char>(c));
        } else {
            out.push_back('%');
            out.push_back(kHex[c >> 4]);
            out.push_back(kHex[c & 15]);
        }
    }
    return out;
}

std::string sanitized_header(beast::string_view value) {
    std::string out(value.substr(0, kMaxLoggedHeader));
    return web::is_metadata_safe(out) ? out : std::string();
}

std::string etag_of(const std::string& path) {
    std::error_code ec;
    const auto size = std::filesystem::file_size(path, ec);
    const auto time = std::filesystem::last_write_time(path, ec).time_since_epoch().count();
    char text[64];
    std::snprintf(text, sizeof text, "\"%llx-%llx\"", static_cast<unsigned long long>(size),
                  static_cast<unsigned long long>(time));
    return text;
}

template <class Stream>
class HttpSession final : public web::Connection, public std::enable_shared_from_this<HttpSession<Stream>> {
public:
    static constexpr bool kTls = std::is_same_v<Stream, TlsStream>;

    HttpSession(WebEndpoint::Impl& endpoint, tcp::socket socket, std::string peer)
        : endpoint_(endpoint), stream_(make_stream(endpoint, std::move(socket))), peer_(std::move(peer)) {}
    ~HttpSession() override {
        if (id_) endpoint_.remove_connection(id_);
    }

    void run() {
        id_ = endpoint_.add_connection(this->shared_from_this());
        asio::dispatch(stream_.get_executor(), [self = this->shared_from_this()] {
            if constexpr (kTls) {
                beast::get_lowest_layer(self->stream_).expires_after(self->endpoint_.options.request_timeout);
                self->stream_.async_handshake(ssl::stream_base::server, [self](beast::error_code ec) {
                    if (ec) return self->close();
                    self->read();
                });
            } else {
                self->read();
            }
        });
    }

    void close_now(bool) override {
        asio::post(stream_.get_executor(), [self = this->shared_from_this()] {
            self->closed_ = true;
            if (self->unary_) self->unary_->context.TryCancel();
            self->close();
        });
    }

private:
    struct UnaryCall {
        grpc::ClientContext context;
        grpc::ByteBuffer request, response;
    };

    static Stream make_stream(WebEndpoint::Impl& endpoint, tcp::socket socket) {
        if constexpr (kTls)
            return Stream(std::move(socket), *endpoint.tls);
        else
            return Stream(std::move(socket));
    }

    void read() {
        if (closed_) return;
        parser_.emplace();
        parser_->header_limit(web::kHeaderLimit);
        parser_->body_limit(web::kMaxRequestBytes);
        beast::get_lowest_layer(stream_).expires_after(endpoint_.options.request_timeout);
        http::async_read(stream_, buffer_, *parser_,
                         [self = this->shared_from_this()](beast::error_code ec, std::size_t) { self->on_read(ec); });
    }

    void on_read(beast::error_code ec) {
        if (closed_) return;
        if (ec == http::error::header_limit)
            return respond_text(
                http::status::request_header_fields_too_large,
                "request line and headers: over the limit of " + std::to_string(web::kHeaderLimit) + " bytes", false);
        if (ec == http::error::body_limit)
            return respond_text(http::status::payload_too_large,
                                "request body: over the limit of " + std::to_string(web::kMaxRequestBytes) +
                                    " bytes (the size cap of a catgs.v1 request)",
                                false);
        // The client left, or took longer than kRequestTimeout to send one request.
        if (ec == http::error::end_of_stream || ec == beast::error::timeout || ec == asio::error::operation_aborted ||
            ec == asio::error::eof || ec == asio::error::connection_reset)
            return close();
        if (ec) return respond_text(http::status::bad_request, "bad HTTP request: " + ec.message(), false);
        request_ = parser_->release();
        route();
    }

    void route() {
        const std::string target(request_.target());
        const std::string path = target.substr(0, target.find('?'));
        const http::verb method = request_.method();
        if (path == "/ws/stream") {
            if (!beast::websocket::is_upgrade(request_))
                return respond_text(http::status::upgrade_required,
                                    "/ws/stream: a WebSocket endpoint (send Upgrade: websocket)", false);
            beast::get_lowest_layer(stream_).expires_never();
            // From here the connection is the WebSocket bridge's; this object ends.
            closed_ = handed_over_ = true;
            return start_websocket(endpoint_, std::move(stream_), std::move(request_), peer_);
        }
        if (path == "/healthz") {
            if (method != http::verb::get && method != http::verb::head) return method_not_allowed("GET, HEAD");
            const bool serving = endpoint_.serving();
            return respond_text(serving ? http::status::ok : http::status::service_unavailable,
                                serving ? "SERVING" : "NOT_SERVING", request_.keep_alive(), "no-store");
        }
        if (path.rfind("/api/", 0) == 0) {
            if (method != http::verb::post) return method_not_allowed("POST");
            return start_unary(path.substr(4));
        }
        if (method != http::verb::get && method != http::verb::head) return method_not_allowed("GET, HEAD");
        serve_static(target);
    }

    void method_not_allowed(const char* allow) {
        auto response = text_response(http::status::method_not_allowed,
                                      std::string(request_.method_string()) + " " + std::string(request_.target()) +
                                          ": method not allowed here (allowed: " + allow + ")",
                                      request_.keep_alive(), "no-store");
        response.set(http::field::allow, allow);
        send(std::move(response));
    }

    void start_unary(const std::string& method) {
        const bool keep_alive = request_.keep_alive();
        if (std::find(kWebUnaryMethods.begin(), kWebUnaryMethods.end(), method) == kWebUnaryMethods.end())
            return respond_status({grpc::StatusCode::UNIMPLEMENTED, "/api" + method +
                                                                        ": not a method of the web API (it serves "
                                                                        "SceneService ListScenes and GetScene, "
                                                                        "RenderService Render)"},
                                  keep_alive);
        const auto type = request_[http::field::content_type];
        if (type.substr(0, std::string_view(kProtobufType).size()) != kProtobufType)
            return respond_status({grpc::StatusCode::INVALID_ARGUMENT,
                                   "content-type '" + std::string(type) + "': send the request as " + kProtobufType},
                                  keep_alive);
        auto call = std::make_shared<UnaryCall>();
        grpc::Status refused;
        if (!add_call_metadata(&call->context, request_, peer_, &refused)) return respond_status(refused, keep_alive);
        call->context.set_deadline(std::chrono::system_clock::now() + web::kUnaryDeadline);
        grpc::Slice slice(request_.body().data(), request_.body().size());
        call->request = grpc::ByteBuffer(&slice, 1);
        unary_ = call;
        endpoint_.call_started();
        auto self = this->shared_from_this();
        endpoint_.stub.UnaryCall(&call->context, method, grpc::StubOptions(), &call->request, &call->response,
                                 [self, call, keep_alive, endpoint = &endpoint_](grpc::Status status) {
                                     // A gRPC thread: hand the answer to the connection's strand.
                                     asio::post(self->stream_.get_executor(), [self, call, status, keep_alive] {
                                         self->unary_.reset();
                                         if (self->closed_) return;
                                         if (!status.ok()) return self->respond_status(status, keep_alive);
                                         auto response =
                                             self->text_response(http::status::ok, {}, keep_alive, "no-store");
                                         // Binary: text_response's trailing newline would corrupt it.
                                         response.body() = byte_buffer_to_string(call->response);
                                         response.prepare_payload();
                                         response.set(http::field::content_type, kProtobufType);
                                         response.set("grpc-status", "0");
                                         self->send(std::move(response));
                                     });
                                     endpoint->call_ended();
                                 });
    }

    void respond_status(const grpc::Status& status, bool keep_alive) {
        auto response = text_response(static_cast<http::status>(web::http_status_for(status.error_code())),
                                      web::status_text(status), keep_alive, "no-store");
        response.set("grpc-status", std::to_string(static_cast<int>(status.error_code())));
        response.set("grpc-message", percent_encode_header(status.error_message()));
        send(std::move(response));
    }

    void serve_static(const std::string& target) {
        const bool keep_alive = request_.keep_alive();
        if (endpoint_.root.empty()) {
            auto response = text_response(http::status::not_found, kViewerNotBuilt, keep_alive, "no-store");
            response.set(http::field::content_type, "text/html; charset=utf-8");
            return send(std::move(response));
        }
        const web::StaticPath file = web::resolve_static_path(endpoint_.root, target);
        if (!file.error.empty())
            return respond_text(static_cast<http::status>(file.http_status), file.error, keep_alive, "no-store");
        const std::string etag = etag_of(file.path);
        if (request_[http::field::if_none_match] == etag) {
            http::response<http::empty_body> response{http::status::not_modified, request_.version()};
            common_headers(response, keep_alive, "no-cache");
            response.set(http::field::etag, etag);
            return send(std::move(response));
        }
        http::file_body::value_type body;
        beast::error_code ec;
        body.open(file.path.c_str(), beast::file_mode::scan, ec);
        if (ec) return respond_text(http::status::not_found, "cannot open " + std::string(target), keep_alive);
        const auto size = body.size();
        // Revalidated on every load (the viewer's file names carry no content hash): a rebuilt
        // viewer is never shadowed by a cached one, and an unchanged file costs a 304.
        auto set_headers = [&](auto& response) {
            common_headers(response, keep_alive, "no-cache");
            response.set(http::field::content_type, web::content_type_for(file.path));
            response.set(http::field::etag, etag);
        };
        if (request_.method() == http::verb::head) {
            http::response<http::empty_body> response{http::status::ok, request_.version()};
            set_headers(response);
            response.content_length(size);
            return send(std::move(response));
        }
        http::response<http::file_body> response{std::piecewise_construct, std::make_tuple(std::move(body)),
                                                 std::make_tuple(http::status::ok, request_.version())};
        set_headers(response);
        response.content_length(size);
        send(std::move(response));
    }

    template <class Response>
    void common_headers(Response& response, bool keep_alive, const char* cache) {
        response.set(http::field::server, kServerName);
        response.set(http::field::cache_control, cache);
        response.set("x-content-type-options", "nosniff");
        // Tokens may travel in the query string (?token=): never in a Referer.
        response.set("referrer-policy", "no-referrer");
        response.keep_alive(keep_alive);
    }

    http::response<http::string_body> text_response(http::status status, std::string body, bool keep_alive,
                                                    const char* cache = "no-store") {
        http::response<http::string_body> response{status, request_.version() ? request_.version() : 11};
        common_headers(response, keep_alive, cache);
        response.set(http::field::content_type, "text/plain; charset=utf-8");
        if (!body.empty() && body.back() != '\n') body += '\n';
        response.body() = std::move(body);
        response.prepare_payload();
        return response;
    }

    void respond_text(http::status status, std::string body, bool keep_alive, const char* cache = "no-store") {
        send(text_response(status, std::move(body), keep_alive, cache));
    }

    template <class Body>
    void send(http::response<Body> response) {
        if (closed_) return;
        auto held = std::make_shared<http::response<Body>>(std::move(response));
        beast::get_lowest_layer(stream_).expires_after(endpoint_.options.request_timeout);
        http::async_write(stream_, *held, [self = this->shared_from_this(), held](beast::error_code ec, std::size_t) {
            if (ec) return self->close();
            if (held->need_eof()) return self->linger();
            self->read();
        });
    }

    /// After a response that ends the connection: stop sending, and discard what the client
    /// still sends (for a bounded time) before closing. Closing with unread bytes would reset
    /// the connection, and the reset can destroy the response before the client reads it.
    void linger() {
        auto& socket = beast::get_lowest_layer(stream_);
        if (!lingering_) {  // one deadline for the whole drain, however the client trickles
            lingering_ = true;
            beast::error_code ignored;
            socket.socket().shutdown(tcp::socket::shutdown_send, ignored);
            socket.expires_after(kLinger);
        }
        socket.async_read_some(asio::buffer(discard_),
                               [self = this->shared_from_this()](beast::error_code ec, std::size_t) {
                                   if (ec || self->closed_) return self->close();
                                   self->linger();
                               });
    }

    void close() {
        closed_ = true;
        if (handed_over_) return;  // the stream was moved to the WebSocket bridge
        beast::error_code ignored;
        beast::get_lowest_layer(stream_).socket().shutdown(tcp::socket::shutdown_both, ignored);
        beast::get_lowest_layer(stream_).close();
    }

    WebEndpoint::Impl& endpoint_;
    Stream stream_;
    std::string peer_;
    std::uint64_t id_ = 0;
    beast::flat_buffer buffer_{web::kHeaderLimit + web::kMaxRequestBytes};
    std::optional<http::request_parser<http::string_body>> parser_;
    HttpRequest request_;
    std::shared_ptr<UnaryCall> unary_;
    std::array<char, 4096> discard_;
    bool closed_ = false, handed_over_ = false, lingering_ = false;
};

}  // namespace

std::string byte_buffer_to_string(const grpc::ByteBuffer& buffer) {
    std::vector<grpc::Slice> slices;
    std::string out;
    if (!buffer.Dump(&slices).ok()) return out;
    out.reserve(buffer.Length());
    for (const grpc::Slice& s : slices) out.append(reinterpret_cast<const char*>(s.begin()), s.size());
    return out;
}

std::string request_token(const HttpRequest& request) {
    static const std::string kBearer = "Bearer ";
    const auto header = request[http::field::authorization];
    if (!header.empty()) {
        const std::string value(header);
        return value.rfind(kBearer, 0) == 0 ? value.substr(kBearer.size()) : value;
    }
    return web::query_parameter(std::string(request.target()), "token").value_or("");
}

bool add_call_metadata(grpc::ClientContext* context, const HttpRequest& request, const std::string& peer,
                       grpc::Status* refused) {
    const std::string token = request_token(request);
    if (!token.empty()) {
        if (!web::is_metadata_safe(token)) {
            *refused = {grpc::StatusCode::UNAUTHENTICATED,
                        "token: contains characters outside printable ASCII; it cannot be the server's token"};
            return false;
        }
        context->AddMetadata("authorization", "Bearer " + token);
    }
    std::string logged_peer = peer;
    if (const std::string forwarded = sanitized_header(request["x-forwarded-for"]); !forwarded.empty())
        logged_peer += ", forwarded for " + forwarded;
    context->AddMetadata("x-catgs-web-peer", logged_peer);
    // The proxy's affinity key: browsers cannot set headers on a WebSocket, so the page
    // sends it as ?session= (docs/web.md); a header from a non-browser client works too.
    std::string session = sanitized_header(request["x-catgs-session"]);
    if (session.empty())
        if (auto q = web::query_parameter(std::string(request.target()), "session")) session = sanitized_header(*q);
    if (!session.empty()) context->AddMetadata("x-catgs-session", session);
    return true;
}

void start_http(WebEndpoint::Impl& endpoint, tcp::socket socket) {
    boost::system::error_code ec;
    const auto remote = socket.remote_endpoint(ec);
    std::string peer = ec ? "unknown" : remote.address().to_string() + ":" + std::to_string(remote.port());
    peer = "web " + peer;
    if (endpoint.tls)
        std::make_shared<HttpSession<TlsStream>>(endpoint, std::move(socket), std::move(peer))->run();
    else
        std::make_shared<HttpSession<PlainStream>>(endpoint, std::move(socket), std::move(peer))->run();
}

}  // namespace catgs::server
