// State shared by every RPC of one server: configuration, scenes, admission, worker pools,
// counters and the list of open streams (for draining on shutdown).
#pragma once

#include <grpcpp/grpcpp.h>

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <vector>

#include "catgs/renderer.hpp"
#include "catgs/server/admission.hpp"
#include "catgs/server/scene_registry.hpp"
#include "catgs/server/worker_pool.hpp"

namespace catgs::server {

struct ServerOptions {
    std::string address = "0.0.0.0:50051";
    /// Optional second, plaintext listener serving only grpc.health.v1 (Kubernetes probes
    /// connect without TLS or tokens). Empty: none.
    std::string health_address;
    std::string scene_root;
    /// Scenes loaded at start-up, each "[ID=]SOURCE" (SOURCE may be any path: it is the
    /// operator's, not a client's).
    std::vector<std::string> preload{"city=builtin:city?gaussians=200000&seed=1"};
    std::string backend = "cpu";
    std::string precision = "float";
    int render_threads = 0;   ///< CPU backend threads per render (0: all cores)
    int render_workers = 2;   ///< sessions rendering at once
    int encode_workers = 2;   ///< encoder threads
    Limits limits;
    std::string tls_cert_file, tls_key_file, tls_client_ca_file;
    std::string bearer_token;  ///< empty: no token required
    bool reflection = true;
    int shutdown_grace_ms = 5000;
};

/// Server-wide counters; gauges are current values, the rest totals.
struct ServerStats {
    std::uint64_t sessions_opened = 0;
    int sessions_active = 0;               ///< admitted sessions (gauge)
    int streams_open = 0;                  ///< Stream reactors alive, admitted or not (gauge)
    std::uint64_t frames_sent = 0;
    std::uint64_t poses_coalesced = 0;
    std::uint64_t frames_coalesced = 0;
    std::uint64_t frame_errors = 0;
    std::int64_t frames_buffered = 0;      ///< encoded frames held by all sessions' output slots (gauge)
    std::int64_t bytes_buffered = 0;       ///< their bytes (gauge)
    std::int64_t peak_session_buffered = 0;  ///< most frames one session ever held at once
};

class StreamSession;

class ServerCore {
public:
    explicit ServerCore(ServerOptions options);
    ~ServerCore();

    const ServerOptions& options() const { return options_; }
    SceneRegistry& scenes() { return scenes_; }
    Admission& admission() { return admission_; }
    WorkerPool& render_pool() { return render_pool_; }
    WorkerPool& encode_pool() { return encode_pool_; }
    WorkerPool& admin_pool() { return admin_pool_; }

    /// OK, or UNAUTHENTICATED when a bearer token is configured and the call lacks it.
    grpc::Status authorize(const grpc::CallbackServerContext* context) const;
    /// A renderer for one session, on the configured backend. Slow on CUDA (allocations):
    /// call from a worker.
    std::unique_ptr<Renderer> make_session_renderer() const;

    void add_stream(const std::shared_ptr<StreamSession>& session);
    void remove_stream(StreamSession* session);
    std::vector<std::shared_ptr<StreamSession>> streams() const;

    struct Counters {
        std::atomic<std::uint64_t> sessions_opened{0}, frames_sent{0}, poses_coalesced{0}, frames_coalesced{0},
            frame_errors{0};
        std::atomic<std::int64_t> frames_buffered{0}, bytes_buffered{0}, peak_session_buffered{0};
        std::atomic<std::uint64_t> next_session_id{1};
    };
    Counters& counters() { return counters_; }
    ServerStats stats() const;
    /// Stops the worker pools (after the gRPC server has shut down).
    void stop_workers();

private:
    ServerOptions options_;
    SceneRegistry scenes_;
    Admission admission_;
    Counters counters_;
    WorkerPool render_pool_;
    WorkerPool encode_pool_;
    WorkerPool admin_pool_;  ///< scene loads: slow, kept off the render workers
    mutable std::mutex streams_mutex_;
    std::set<std::shared_ptr<StreamSession>> streams_;
};

}  // namespace catgs::server
