// The WebSocket bridge: one browser WebSocket is one RenderService.Stream call on the server's
// in-process channel. Binary messages are forwarded as unparsed bytes both ways, so the
// stream session parses, validates, limits and drains them exactly as for a gRPC client;
// this file only adds what a WebSocket needs: message types and sizes, and the call's status
// as the close code and reason (docs/web.md).
//
// Threads: Beast runs on the connection's strand; gRPC's reactions (OnReadDone, OnWriteDone,
// OnDone) run on gRPC threads and only post to that strand. A hold (AddHold) keeps OnDone
// from running while the strand may still start a read or write; it is released once, when
// neither side will start another (the call's reads ended, or the browser is gone).
//
// Backpressure: one frame at a time. The next frame is read from the call only after the
// previous one is written to the socket, so a browser that does not read stalls the
// session's own write, and its stall watchdog ends the call; the next browser message is
// read only after the previous one is in gRPC's hands. With no read pending, the end of the
// call cannot reach the bridge (the hold keeps OnDone back), so a frame write that outlasts
// WebOptions::frame_write_timeout gives the call up and closes the socket itself.
#include <boost/beast/websocket.hpp>
#include <boost/beast/websocket/ssl.hpp>
#include <spdlog/spdlog.h>

#include "web_internal.hpp"

namespace catgs::server {
namespace {

namespace websocket = beast::websocket;

constexpr const char* kStreamMethod = "/catgs.v1.RenderService/Stream";

template <class Stream>
class WsSession final : public web::Connection,
                        public grpc::ClientBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>,
                        public std::enable_shared_from_this<WsSession<Stream>> {
public:
    WsSession(WebEndpoint::Impl& endpoint, Stream stream, HttpRequest request, std::string peer)
        : endpoint_(endpoint),
          ws_(std::move(stream)),
          request_(std::move(request)),
          peer_(std::move(peer)),
          teardown_(ws_.get_executor()),
          write_deadline_(ws_.get_executor()) {}
    ~WsSession() override {
        if (id_) endpoint_.remove_connection(id_);
    }

    void run() {
        id_ = endpoint_.add_connection(this->shared_from_this());
        ws_.set_option(websocket::stream_base::timeout{endpoint_.options.request_timeout, web::kWebSocketIdleTimeout,
                                                       /*keep_alive_pings=*/true});
        ws_.set_option(websocket::stream_base::decorator(
            [](websocket::response_type& response) { response.set(http::field::server, "catgs-server"); }));
        // No limit in Beast: it would fail the connection with 1009 and no reason. The size
        // cap is checked here as the pieces of a message arrive (read_ws).
        ws_.read_message_max(0);
        ws_.auto_fragment(false);
        ws_.binary(true);
        asio::dispatch(ws_.get_executor(), [self = this->shared_from_this()] {
            self->ws_.async_accept(self->request_, [self](beast::error_code ec) {
                if (ec) return self->close_socket();
                self->start_call();
            });
        });
    }

    void close_now(bool hard) override {
        asio::post(ws_.get_executor(), [self = this->shared_from_this(), hard] {
            if (self->closing_ && !hard) return;  // its close frame is on the way
            self->give_up();
            self->close_socket();
        });
    }

    // gRPC's reactions: on gRPC threads, they only hand over to the strand.
    void OnReadDone(bool ok) override {
        asio::post(ws_.get_executor(), [self = this->shared_from_this(), ok] { self->on_frame(ok); });
    }
    void OnWriteDone(bool ok) override {
        asio::post(ws_.get_executor(), [self = this->shared_from_this(), ok] { self->on_request_sent(ok); });
    }
    void OnDone(const grpc::Status& status) override {
        WebEndpoint::Impl& endpoint = endpoint_;  // `this` may be gone once the post runs
        asio::post(ws_.get_executor(), [self = std::move(self_), status] { self->on_call_done(status); });
        endpoint.call_ended();
    }

private:
    void start_call() {
        grpc::Status refused;
        if (!add_call_metadata(&context_, request_, peer_, &refused)) return close_with(refused);
        self_ = this->shared_from_this();  // until OnDone
        call_started_ = true;
        endpoint_.call_started();
        endpoint_.stub.PrepareBidiStreamingCall(&context_, kStreamMethod, grpc::StubOptions(), this);
        AddHold();
        StartRead(&from_server_);
        StartCall();
        read_ws();
    }

    /// The next piece of a browser message.
    void read_ws() {
        if (ws_gone_ || reading_ || closing_) return;
        reading_ = true;
        ws_.async_read_some(
            message_, web::kReadChunkBytes,
            [self = this->shared_from_this()](beast::error_code ec, std::size_t) { self->on_ws_read(ec); });
    }

    void on_ws_read(beast::error_code ec) {
        reading_ = false;
        if (ec) {
            // The browser closed, the connection failed, or it timed out: end the call.
            ws_gone_ = true;
            give_up();
            return;
        }
        if (!ws_.got_binary())
            return close_with(websocket::close_code::unknown_data,
                              "text message: send each catgs.v1.StreamRequest as one binary message");
        if (message_.size() > web::kMaxRequestBytes)
            return close_with(websocket::close_code::too_big, "message over " + std::to_string(web::kMaxRequestBytes) +
                                                                  " bytes: the size cap of a catgs.v1.StreamRequest");
        if (!ws_.is_message_done()) return read_ws();
        if (hold_released_) {
            message_.clear();  // the call is over; its status is on the way
            return read_ws();
        }
        grpc::Slice slice(message_.data().data(), message_.size());
        to_server_ = grpc::ByteBuffer(&slice, 1);
        message_.clear();
        StartWrite(&to_server_);  // the next message is read once gRPC has this one (OnWriteDone)
    }

    void on_request_sent(bool ok) {
        // Not ok: the call is ending and OnDone brings its status; keep reading meanwhile so
        // that a browser's close is seen.
        (void)ok;
        read_ws();
    }

    void on_frame(bool ok) {
        if (!ok) return release_hold();  // the session finished; its status follows in OnDone
        if (ws_gone_ || hold_released_) return;
        frame_ = byte_buffer_to_string(from_server_);
        from_server_.Clear();
        writing_ = true;
        if (const auto timeout = endpoint_.options.frame_write_timeout; timeout.count() > 0) {
            write_deadline_.expires_after(timeout);
            write_deadline_.async_wait([self = this->shared_from_this()](beast::error_code ec) {
                if (ec || !self->writing_) return;
                spdlog::info("{}: a frame waited {} ms for the browser to read it; closing the WebSocket", self->peer_,
                             self->endpoint_.options.frame_write_timeout.count());
                self->give_up();
                self->close_socket();
            });
        }
        ws_.async_write(asio::buffer(frame_), [self = this->shared_from_this()](beast::error_code ec, std::size_t) {
            self->on_frame_written(ec);
        });
    }

    void on_frame_written(beast::error_code ec) {
        writing_ = false;
        write_deadline_.cancel();
        frame_.clear();
        frame_.shrink_to_fit();  // one frame's memory at a time, not the largest ever
        if (ec) {
            ws_gone_ = true;
            give_up();
            return;
        }
        if (!hold_released_) StartRead(&from_server_);
    }

    void on_call_done(const grpc::Status& status) {
        call_done_ = true;
        if (ws_gone_) return close_socket();
        if (closing_) return;
        spdlog::debug("{}: stream ended, {}", peer_, web::status_text(status));
        close_with(static_cast<websocket::close_code>(web::close_code_for(status.error_code())),
                   web::status_text(status, web::kCloseReasonBytes), false);
    }

    void close_with(const grpc::Status& status) {
        close_with(static_cast<websocket::close_code>(web::close_code_for(status.error_code())),
                   web::status_text(status, web::kCloseReasonBytes));
    }

    /// Sends a close frame with `reason` (cut to a close frame's size) and ends the call if it
    /// still runs (`end_call`).
    void close_with(websocket::close_code code, std::string reason, bool end_call = true) {
        if (closing_ || ws_gone_) return;
        if (end_call) give_up();
        closing_ = true;
        // Status texts come cut at a character boundary; the bridge's own reasons are ASCII.
        if (reason.size() > web::kCloseReasonBytes) reason.resize(web::kCloseReasonBytes);
        // A browser that does not read may never take the close frame: do not wait for it
        // longer than a handshake.
        teardown_.expires_after(endpoint_.options.request_timeout);
        teardown_.async_wait([self = this->shared_from_this()](beast::error_code ec) {
            if (!ec) self->close_socket();
        });
        ws_.async_close(websocket::close_reason(code, reason), [self = this->shared_from_this()](beast::error_code) {
            self->teardown_.cancel();
            self->close_socket();
        });
    }

    /// Ends the call (if it runs) and stops starting gRPC operations.
    void give_up() {
        if (call_started_ && !call_done_) context_.TryCancel();
        release_hold();
    }

    void release_hold() {
        if (!call_started_ || hold_released_) return;
        hold_released_ = true;
        RemoveHold();
    }

    void close_socket() {
        ws_gone_ = true;
        beast::get_lowest_layer(ws_).close();
    }

    WebEndpoint::Impl& endpoint_;
    websocket::stream<Stream> ws_;
    HttpRequest request_;
    std::string peer_;
    asio::steady_timer teardown_;
    asio::steady_timer write_deadline_;  ///< the frame being written must leave by then
    std::uint64_t id_ = 0;

    grpc::ClientContext context_;
    std::shared_ptr<WsSession> self_;  ///< the call's reference, dropped by OnDone
    grpc::ByteBuffer from_server_, to_server_;
    beast::flat_buffer message_;  ///< the browser's message being read (at most the cap + a piece)
    std::string frame_;           ///< the frame being written to the browser
    // Strand state.
    bool call_started_ = false, call_done_ = false, hold_released_ = false;
    bool reading_ = false, writing_ = false, closing_ = false, ws_gone_ = false;
};

template <class Stream>
void start(WebEndpoint::Impl& endpoint, Stream stream, HttpRequest request, std::string peer) {
    std::make_shared<WsSession<Stream>>(endpoint, std::move(stream), std::move(request), std::move(peer))->run();
}

}  // namespace

void start_websocket(WebEndpoint::Impl& endpoint, PlainStream stream, HttpRequest request, std::string peer) {
    start(endpoint, std::move(stream), std::move(request), std::move(peer));
}

void start_websocket(WebEndpoint::Impl& endpoint, TlsStream stream, HttpRequest request, std::string peer) {
    start(endpoint, std::move(stream), std::move(request), std::move(peer));
}

}  // namespace catgs::server
