#include "catgs/server/server.hpp"

#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/generic/async_generic_service.h>
#include <grpcpp/health_check_service_interface.h>
#include <grpcpp/impl/server_builder_option.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <fstream>
#include <sstream>
#include <thread>

#include "catgs/common/files.hpp"
#include "catgs/error.hpp"
#include "catgs/common/net_config.hpp"
#include "catgs/server/services.hpp"
#include "catgs/server/stream_session.hpp"
#include "catgs/server/web_endpoint.hpp"

namespace catgs::server {
namespace {

std::shared_ptr<grpc::ServerCredentials> credentials(const ServerOptions& o) {
    if (o.tls_cert_file.empty() && o.tls_key_file.empty()) {
        if (!o.tls_client_ca_file.empty())
            throw Error(
                "--tls-client-ca needs --tls-cert and --tls-key: client certificates are only checked over TLS");
        return grpc::InsecureServerCredentials();
    }
    if (o.tls_cert_file.empty() || o.tls_key_file.empty())
        throw Error("--tls-cert and --tls-key: give both or neither");
    grpc::SslServerCredentialsOptions ssl;
    ssl.pem_key_cert_pairs.push_back(
        {read_file(o.tls_key_file, "--tls-key"), read_file(o.tls_cert_file, "--tls-cert")});
    if (!o.tls_client_ca_file.empty()) {
        // mTLS: clients must present a certificate signed by this CA.
        ssl.pem_root_certs = read_file(o.tls_client_ca_file, "--tls-client-ca");
        ssl.client_certificate_request = GRPC_SSL_REQUEST_AND_REQUIRE_CLIENT_CERTIFICATE_AND_VERIFY;
    }
    return grpc::SslServerCredentials(ssl);
}

/// Removes gRPC's reflection plugin from one server: InitProtoReflectionServerBuilderPlugin
/// registers it for every server the process builds afterwards.
class WithoutReflection final : public grpc::ServerBuilderOption {
public:
    void UpdateArguments(grpc::ChannelArguments*) override {}
    void UpdatePlugins(std::vector<std::unique_ptr<grpc::ServerBuilderPlugin>>* plugins) override {
        std::erase_if(*plugins, [](const auto& p) { return p && p->name() == "proto_server_reflection"; });
    }
};

/// The health listener's answer to every method but grpc.health.v1's. It also gives that
/// server a callback method, without which gRPC refuses to build it (it has no other
/// service until the default health service is added at start).
class HealthPortOnly final : public grpc::CallbackGenericService {
public:
    grpc::ServerGenericBidiReactor* CreateReactor(grpc::GenericCallbackServerContext* context) override {
        class Reactor : public grpc::ServerGenericBidiReactor {
        public:
            explicit Reactor(const std::string& method) {
                Finish({grpc::StatusCode::UNIMPLEMENTED,
                        "this port serves only grpc.health.v1.Health (the health listener), not " + method});
            }
            void OnDone() override { delete this; }
        };
        return new Reactor(context->method());
    }
};

/// How long a drained stream's frame in flight may take to reach a reading client; a stream
/// still open after that has a client that does not read, and is cancelled.
constexpr std::chrono::milliseconds kDrainWriteWait{1000};
/// How long the cancels of those streams may take to complete.
constexpr std::chrono::milliseconds kCancelWait{1000};

/// Polls `done` every 10 ms until it holds or `wait` has passed.
template <typename Done>
bool wait_until(Done done, std::chrono::milliseconds wait) {
    const auto end = std::chrono::steady_clock::now() + wait;
    while (!done()) {
        if (std::chrono::steady_clock::now() >= end) return false;
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return true;
}

/// Web connections beyond --max-sessions: page loads, scene calls and refused streams need
/// connections too, without holding a session.
constexpr int kWebConnectionMargin = 32;
/// A browser's frame write may outlast the session's stall watchdog by this much: the
/// watchdog ends the call first (and counts the stall), then the endpoint frees the socket.
/// The watchdog starts only when the session's next frame is rendered and cannot be written,
/// so the margin must cover a render: at 1 s, a loaded 2-core host rendering 1.7 s frames saw
/// the endpoint close the socket first, and the stall went uncounted. A dead socket is held
/// this much longer, nothing else.
constexpr std::chrono::milliseconds kWebStallMargin{5000};

/// Service names whose health is reported (plus "", the whole server).
const char* const kServiceNames[] = {"catgs.v1.RenderService", "catgs.v1.SceneService"};

void set_health(grpc::Server* server, bool serving) {
    if (!server) return;
    grpc::HealthCheckServiceInterface* health = server->GetHealthCheckService();
    if (!health) return;
    health->SetServingStatus(serving);  // every service, "" included
    for (const char* name : kServiceNames) health->SetServingStatus(name, serving);
}

}  // namespace

Server::Server(ServerOptions options) : core_(std::make_unique<ServerCore>(std::move(options))) {}

Server::~Server() {
    bool running;
    {
        std::lock_guard lock(mutex_);
        running = server_ && !stopped_;
    }
    if (running) shutdown(std::chrono::milliseconds(core_->options().shutdown_grace_ms));
    core_->stop_workers();
}

void Server::start() {
    const ServerOptions& o = core_->options();
    // Fail on a bad backend before listening, not at the first session.
    core_->make_session_renderer();

    for (const std::string& spec : o.preload) {
        // "[ID=]SOURCE": an '=' before any ':' separates an id (builtin specs contain '=' later).
        std::string id, source = spec;
        const auto eq = spec.find('='), colon = spec.find(':');
        if (eq != std::string::npos && (colon == std::string::npos || eq < colon)) {
            id = spec.substr(0, eq);
            source = spec.substr(eq + 1);
        }
        SceneSummary summary;
        grpc::Status status = core_->scenes().load(id, source, false, true, &summary);
        if (!status.ok()) throw Error("--scene '" + spec + "': " + status.error_message());
        core_->prewarm(summary.id);
    }

    render_service_ = std::make_unique<RenderServiceImpl>(*core_);
    scene_service_ = std::make_unique<SceneServiceImpl>(*core_);
    grpc::EnableDefaultHealthCheckService(true);
    // Explicit: the plugin's static initialiser is dropped by --as-needed linking otherwise.
    // Reflection answers without a token (it is not ours to authorize), so it is off
    // whenever a token is required.
    const bool reflection = o.reflection && o.bearer_token.empty();
    if (o.reflection && !reflection) spdlog::info("reflection is off: a bearer token is required (--token-file)");
    grpc::reflection::InitProtoReflectionServerBuilderPlugin();

    grpc::ServerBuilder builder;
    if (!reflection) builder.SetOption(std::make_unique<WithoutReflection>());
    builder.AddListeningPort(o.address, credentials(o), &port_);
    builder.RegisterService(render_service_.get());
    builder.RegisterService(scene_service_.get());
    net::apply_server_args(builder);
    server_ = builder.BuildAndStart();
    if (!server_ || port_ == 0) throw Error("--address '" + o.address + "': cannot listen there");
    set_health(server_.get(), true);

    if (!o.health_address.empty()) {
        // Plaintext, health only: Kubernetes' gRPC probe speaks neither TLS nor tokens.
        grpc::ServerBuilder health_builder;
        health_builder.SetOption(std::make_unique<WithoutReflection>());
        health_generic_ = std::make_unique<HealthPortOnly>();
        health_builder.RegisterCallbackGenericService(health_generic_.get());
        health_builder.AddListeningPort(o.health_address, grpc::InsecureServerCredentials(), &health_port_);
        health_server_ = health_builder.BuildAndStart();
        if (!health_server_ || health_port_ == 0)
            throw Error("--health-address '" + o.health_address + "': cannot listen there");
        set_health(health_server_.get(), true);
    }
    if (!o.web_address.empty()) {
        // A client of this server's own services: every stream session rule applies to browsers.
        WebOptions web{o.web_address, o.web_root, o.tls_cert_file, o.tls_key_file,
                       o.limits.max_sessions + kWebConnectionMargin};
        if (o.limits.stall_timeout_ms > 0)
            web.frame_write_timeout = std::chrono::milliseconds(o.limits.stall_timeout_ms) + kWebStallMargin;
        web_ = std::make_unique<WebEndpoint>(web, server_->InProcessChannel(net::client_channel_args()),
                                             [this] { return !core_->admission().draining(); });
        web_->start();
        spdlog::info("web viewer on {} (WebSocket /ws/stream, web root {})", web_->url(), o.web_root);
    }
    spdlog::info(
        "catgs-server listening on port {} ({}, backend {}, {} render workers, {} encoders, max {} sessions){}", port_,
        o.tls_cert_file.empty() ? "plaintext" : "TLS", o.backend, o.render_workers, o.encode_workers,
        o.limits.max_sessions, health_port_ ? ", health on port " + std::to_string(health_port_) : "");
}

void Server::begin_shutdown() {
    {
        std::lock_guard lock(mutex_);
        if (shutting_down_) return;
        shutting_down_ = true;
    }
    spdlog::info("shutting down: health NOT_SERVING, refusing new sessions, draining {} stream(s)",
                 core_->streams().size());
    set_health(server_.get(), false);
    set_health(health_server_.get(), false);
    core_->admission().drain();
    for (const auto& session : core_->streams()) session->drain(shutting_down_status());
}

void Server::shutdown(std::chrono::milliseconds grace) {
    begin_shutdown();
    {
        std::lock_guard lock(mutex_);
        if (stopped_) return;
    }
    end_streams(std::min(grace, kDrainWriteWait));
    // Before gRPC stops: the web endpoint's calls run on its in-process channel.
    if (web_) web_->stop();
    const auto deadline = std::chrono::system_clock::now() + grace;
    // Streams have ended above; unary calls (scene loads, renders) get until the deadline, and
    // so do clients to close their connections after gRPC's GOAWAY.
    if (server_) server_->Shutdown(deadline);
    core_->stop_workers();
    if (health_server_) health_server_->Shutdown(std::chrono::system_clock::now());
    {
        std::lock_guard lock(mutex_);
        stopped_ = true;
    }
    stopped_cv_.notify_all();
    spdlog::info("shut down");
}

void Server::drain_and_shutdown() {
    const auto drain = std::chrono::milliseconds(core_->options().drain_ms);
    const auto drained = std::chrono::steady_clock::now() + drain;
    begin_shutdown();
    spdlog::info("draining for {} ms: the listeners stay open, new sessions are refused", drain.count());
    end_streams(kDrainWriteWait);
    std::this_thread::sleep_until(drained);
    shutdown(std::chrono::milliseconds(core_->options().shutdown_grace_ms));
}

void Server::end_streams(std::chrono::milliseconds wait) {
    auto all_ended = [this] { return core_->streams().empty(); };
    if (wait_until(all_ended, wait)) return;
    const auto left = core_->streams();
    spdlog::info("cancelling {} stream(s) whose client does not read, with the shutdown status", left.size());
    for (const auto& session : left) session->cancel(shutting_down_status());
    // Their trailers must be on the wire before the server closes the connections.
    if (!wait_until(all_ended, kCancelWait))
        spdlog::warn("{} stream(s) still open after their cancel", core_->streams().size());
}

int Server::web_port() const {
    return web_ ? web_->port() : 0;
}

std::string Server::web_url() const {
    return web_ ? web_->url() : std::string();
}

void Server::wait() {
    std::unique_lock lock(mutex_);
    stopped_cv_.wait(lock, [this] { return stopped_; });
}

}  // namespace catgs::server
