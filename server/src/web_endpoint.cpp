// The web endpoint's life: binding, the accept loop with its connection cap, the registry of
// open connections and gRPC calls, and a stop that leaves no handler behind.
#include <spdlog/spdlog.h>

#include <filesystem>
#include <system_error>

#include "catgs/common/files.hpp"
#include "catgs/error.hpp"
#include "web_internal.hpp"

namespace catgs::server {
namespace {

/// What a connection over the cap gets before it is closed: one small write, no parsing.
constexpr char kTooManyConnections[] =
    "HTTP/1.1 503 Service Unavailable\r\nContent-Type: text/plain\r\nContent-Length: 69\r\n"
    "Connection: close\r\nRetry-After: 1\r\n\r\n"
    "UNAVAILABLE: too many connections to the web endpoint; retry shortly\n";
static_assert(sizeof("UNAVAILABLE: too many connections to the web endpoint; retry shortly\n") - 1 == 69);

tcp::endpoint parse_endpoint(const std::string& address) {
    // host:port, host may be [v6]; an empty host listens on every interface.
    const std::size_t colon = address.rfind(':');
    if (colon == std::string::npos) throw Error("--web-address '" + address + "': expected host:port");
    std::string host = address.substr(0, colon);
    const std::string port_text = address.substr(colon + 1);
    if (host.size() >= 2 && host.front() == '[' && host.back() == ']') host = host.substr(1, host.size() - 2);
    int port = -1;
    try {
        std::size_t used = 0;
        port = std::stoi(port_text, &used);
        if (used != port_text.size()) port = -1;
    } catch (const std::exception&) {
    }
    if (port < 0 || port > 65535) throw Error("--web-address '" + address + "': port must be 0-65535");
    if (host.empty() || host == "*") host = "0.0.0.0";
    if (host == "localhost") host = "127.0.0.1";
    boost::system::error_code ec;
    const asio::ip::address ip = asio::ip::make_address(host, ec);
    if (ec) throw Error("--web-address '" + address + "': host must be an IP address or localhost");
    return {ip, static_cast<unsigned short>(port)};
}

ssl::context make_tls(const WebOptions& o) {
    ssl::context tls(ssl::context::tls_server);
    // TLS 1.2 and 1.3 only, as gRPC's own TLS listener.
    tls.set_options(ssl::context::default_workarounds | ssl::context::no_sslv2 | ssl::context::no_sslv3 |
                    ssl::context::no_tlsv1 | ssl::context::no_tlsv1_1 | ssl::context::single_dh_use);
    const std::string cert = read_file(o.tls_cert_file, "--tls-cert"), key = read_file(o.tls_key_file, "--tls-key");
    boost::system::error_code ec;
    tls.use_certificate_chain(asio::buffer(cert), ec);
    if (ec) throw Error("--tls-cert '" + o.tls_cert_file + "': not a PEM certificate chain (" + ec.message() + ")");
    tls.use_private_key(asio::buffer(key), ssl::context::pem, ec);
    if (ec) throw Error("--tls-key '" + o.tls_key_file + "': not a PEM private key (" + ec.message() + ")");
    return tls;
}

}  // namespace

namespace web {

bool is_metadata_safe(const std::string& value) {
    for (char c : value)
        if (c < 0x20 || c > 0x7e) return false;
    return true;
}

}  // namespace web

WebEndpoint::Impl::Impl(WebOptions o, std::shared_ptr<grpc::Channel> ch, std::function<bool()> serving_fn)
    : options(std::move(o)),
      channel(std::move(ch)),
      stub(channel),
      serving(std::move(serving_fn)),
      acceptor(asio::make_strand(io)) {}

std::uint64_t WebEndpoint::Impl::add_connection(const std::shared_ptr<web::Connection>& connection) {
    std::lock_guard lock(mutex_);
    const std::uint64_t id = next_id_++;
    connections_.emplace(id, connection);
    return id;
}

void WebEndpoint::Impl::remove_connection(std::uint64_t id) {
    {
        std::lock_guard lock(mutex_);
        connections_.erase(id);
    }
    changed_.notify_all();
}

std::size_t WebEndpoint::Impl::connection_count() const {
    std::lock_guard lock(mutex_);
    return connections_.size();
}

void WebEndpoint::Impl::call_started() {
    std::lock_guard lock(mutex_);
    ++calls_;
}

void WebEndpoint::Impl::call_ended() {
    {
        std::lock_guard lock(mutex_);
        --calls_;
    }
    changed_.notify_all();
}

bool WebEndpoint::Impl::stopping() const {
    std::lock_guard lock(mutex_);
    return stopping_;
}

void WebEndpoint::Impl::start() {
    const tcp::endpoint endpoint = parse_endpoint(options.address);
    if (!options.tls_cert_file.empty() || !options.tls_key_file.empty()) {
        if (options.tls_cert_file.empty() || options.tls_key_file.empty())
            throw Error("--tls-cert and --tls-key: give both or neither");
        tls.emplace(make_tls(options));
    }
    std::error_code fs_error;
    const auto canonical = std::filesystem::canonical(options.root.empty() ? "." : options.root, fs_error);
    if (!options.root.empty() && !fs_error && std::filesystem::is_directory(canonical)) root = canonical.string();

    boost::system::error_code ec;
    acceptor.open(endpoint.protocol(), ec);
    if (!ec) acceptor.set_option(asio::socket_base::reuse_address(true), ec);
    if (!ec) acceptor.bind(endpoint, ec);
    if (!ec) acceptor.listen(asio::socket_base::max_listen_connections, ec);
    if (!ec) bound = acceptor.local_endpoint(ec);
    if (ec) throw Error("--web-address '" + options.address + "': cannot listen there (" + ec.message() + ")");
    {
        std::lock_guard lock(mutex_);
        started_ = true;
    }
    accept();
    for (int i = 0; i < std::max(1, options.threads); ++i) threads.emplace_back([this] { io.run(); });
    if (root.empty())
        spdlog::warn("web root '{}' does not exist: GET / answers a page saying how to build the viewer", options.root);
}

void WebEndpoint::Impl::accept() {
    // Each connection gets its own strand: its handlers never run at once, on any thread.
    acceptor.async_accept(asio::make_strand(io), [this](boost::system::error_code ec, tcp::socket socket) {
        if (ec == asio::error::operation_aborted || !acceptor.is_open()) return;
        if (!ec) on_accept(std::move(socket));
        accept();
    });
}

void WebEndpoint::Impl::on_accept(tcp::socket socket) {
    if (connection_count() >= static_cast<std::size_t>(std::max(1, options.max_connections))) {
        auto held = std::make_shared<tcp::socket>(std::move(socket));
        asio::async_write(*held, asio::buffer(kTooManyConnections, sizeof(kTooManyConnections) - 1),
                          [held](boost::system::error_code, std::size_t) {
                              boost::system::error_code ignored;
                              held->shutdown(tcp::socket::shutdown_both, ignored);
                              held->close(ignored);
                          });
        return;
    }
    start_http(*this, std::move(socket));
}

void WebEndpoint::Impl::stop() {
    std::vector<std::weak_ptr<web::Connection>> open;
    {
        std::lock_guard lock(mutex_);
        if (stopping_ || !started_) {
            stopping_ = true;
            return;
        }
        stopping_ = true;
    }
    asio::post(acceptor.get_executor(), [this] {
        boost::system::error_code ignored;
        acceptor.close(ignored);
    });
    auto close_all = [&](bool hard) {
        std::vector<std::shared_ptr<web::Connection>> alive;
        {
            std::lock_guard lock(mutex_);
            for (const auto& [id, weak] : connections_)
                if (auto c = weak.lock()) alive.push_back(std::move(c));
        }
        // Outside the lock: a connection's last reference may go here, and its destructor
        // unregisters itself.
        for (const auto& c : alive) c->close_now(hard);
    };
    close_all(false);
    std::unique_lock lock(mutex_);
    if (!changed_.wait_for(lock, web::kStopGrace, [this] { return connections_.empty(); })) {
        lock.unlock();
        close_all(true);
        lock.lock();
    }
    // gRPC guarantees each cancelled call's last callback; the io threads must outlive it,
    // since that callback posts to its connection's strand.
    if (!changed_.wait_for(lock, web::kCallsEndWait, [this] { return calls_ == 0; })) {
        // Never seen; if it happens, the endpoint's state is kept (leaked) rather than freed
        // under a callback still to come, so that shutdown cannot crash.
        spdlog::error("web endpoint: {} call(s) still running after their cancel; keeping their state", calls_);
        leaked_ = true;
    }
    changed_.wait_for(lock, web::kStopGrace, [this] { return connections_.empty(); });
    const std::size_t left = connections_.size();
    lock.unlock();
    io.stop();
    for (auto& t : threads) t.join();
    threads.clear();
    spdlog::info("web endpoint stopped{}", left ? " (" + std::to_string(left) + " connection(s) dropped)" : "");
}

WebEndpoint::WebEndpoint(WebOptions options, std::shared_ptr<grpc::Channel> channel, std::function<bool()> serving)
    : impl_(std::make_unique<Impl>(std::move(options), std::move(channel), std::move(serving))) {}

WebEndpoint::~WebEndpoint() {
    stop();
    if (impl_->leaked()) static_cast<void>(impl_.release());  // see Impl::stop
}

void WebEndpoint::start() {
    impl_->start();
}

int WebEndpoint::port() const {
    return impl_->bound.port();
}

std::string WebEndpoint::url() const {
    const tcp::endpoint& endpoint = impl_->bound;
    if (endpoint.port() == 0) return "";
    std::string host = endpoint.address().to_string();
    // A wildcard address is not one a browser can open; the same machine reaches it as
    // localhost.
    if (endpoint.address().is_unspecified())
        host = "localhost";
    else if (endpoint.address().is_v6())
        host = "[" + host + "]";
    return std::string(impl_->tls ? "https" : "http") + "://" + host + ":" + std::to_string(endpoint.port()) + "/";
}

void WebEndpoint::stop() {
    impl_->stop();
}

std::size_t WebEndpoint::connections() const {
    return impl_->connection_count();
}

}  // namespace catgs::server
