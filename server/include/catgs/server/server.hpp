// The catgs render server: builds the gRPC server (RenderService, SceneService, health,
// reflection), loads the preloaded scenes and runs the shutdown sequence. Used by the
// catgs-server binary and, in-process, by the integration tests.
#pragma once

#include <grpcpp/generic/async_generic_service.h>
#include <grpcpp/grpcpp.h>

#include <chrono>
#include <memory>

#include "catgs/server/server_core.hpp"

namespace catgs::server {

class RenderServiceImpl;
class SceneServiceImpl;
class WebEndpoint;

class Server {
public:
    explicit Server(ServerOptions options);
    ~Server();

    /// Loads the preloaded scenes and starts listening. Throws catgs::Error for bad options
    /// (unknown backend, unreadable certificate, a port that cannot be bound, bad scene).
    void start();
    /// The bound ports (useful with ":0" addresses); 0 when there is no such listener.
    int port() const { return port_; }
    int health_port() const { return health_port_; }
    /// The web endpoint's port and the URL to open (0 and "" without --web-address).
    int web_port() const;
    std::string web_url() const;

    /// First half of shutdown, returns at once: health turns NOT_SERVING, new sessions are
    /// refused with UNAVAILABLE, open streams end with UNAVAILABLE asking clients to reconnect.
    void begin_shutdown();
    /// begin_shutdown(), then stops the gRPC server (calls still running at the deadline are
    /// cancelled), the workers and the health listener. Streams that did not end by
    /// themselves within a second (a client that does not read) are cancelled with the
    /// shutdown status first, so that they too get its message. Returns within about `grace`
    /// plus that second.
    void shutdown(std::chrono::milliseconds grace);
    /// What SIGTERM does, as Kubernetes expects: begin_shutdown(), then the listeners stay
    /// open for ServerOptions::drain_ms (health answers NOT_SERVING, new sessions get
    /// UNAVAILABLE), then shutdown(shutdown_grace_ms).
    void drain_and_shutdown();
    /// Blocks until shutdown() has completed.
    void wait();

    ServerStats stats() const { return core_->stats(); }
    ServerCore& core() { return *core_; }

private:
    /// Waits up to `wait` for the drained streams to end, cancels those left with the
    /// shutdown status, and waits (bounded) for the cancels to complete.
    void end_streams(std::chrono::milliseconds wait);

    std::unique_ptr<ServerCore> core_;
    std::unique_ptr<RenderServiceImpl> render_service_;
    std::unique_ptr<SceneServiceImpl> scene_service_;
    std::unique_ptr<grpc::Server> server_;
    std::unique_ptr<grpc::CallbackGenericService> health_generic_;
    std::unique_ptr<grpc::Server> health_server_;
    std::unique_ptr<WebEndpoint> web_;
    int port_ = 0, health_port_ = 0;
    std::mutex mutex_;  // a leaf, released before calling into the core (lock order: server_core.hpp)
    std::condition_variable stopped_cv_;
    bool shutting_down_ = false, stopped_ = false;
};

}  // namespace catgs::server
