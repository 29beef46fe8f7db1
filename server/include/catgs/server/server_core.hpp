// State shared by every RPC of one server: configuration, scenes, admission, worker pools,
// counters and the list of open streams (for draining on shutdown).
#pragma once

#include <grpcpp/grpcpp.h>

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "catgs/renderer.hpp"
#include "catgs/server/admission.hpp"
#include "catgs/server/device_placement.hpp"
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
    /// The devices sessions are placed on (--gpus, parse_gpus; docs/multi-gpu.md): CUDA device
    /// indices, or the CPU backend's simulated devices. Default: device 0 alone, one GPU.
    std::vector<int> devices{0};
    std::string precision = "float";
    int render_threads = 0;  ///< CPU backend threads per render (0: all cores)
    int render_workers = 0;  ///< sessions rendering at once (0: auto_worker_counts)
    int encode_workers = 0;  ///< encoder threads (0: auto_worker_counts)
    Limits limits;
    std::string tls_cert_file, tls_key_file, tls_client_ca_file;
    std::string bearer_token;  ///< empty: no token required
    /// Serve gRPC server reflection (never while a bearer token is required: reflection
    /// would answer without one).
    bool reflection = true;
    /// Upload the start-up scenes to every device before their first session (ServerCore::prewarm).
    bool prewarm = true;
    /// On SIGTERM (Server::drain_and_shutdown): how long the listeners stay open after health
    /// turns NOT_SERVING, refusing new sessions with UNAVAILABLE, while load balancers and
    /// Kubernetes endpoints stop sending traffic here.
    int drain_ms = 5000;
    /// After the drain: time given to unary calls still running before they are cancelled.
    int shutdown_grace_ms = 5000;
    /// The web endpoint (docs/web.md): HTTP(S) and WebSocket on this host:port, with the
    /// same TLS and token as gRPC. Empty: none.
    std::string web_address;
    /// The viewer's static files, served by the web endpoint.
    std::string web_root;
    /// Tests only: makes the renderers instead of make_renderer(backend, ...), e.g. to
    /// simulate a device that runs out of memory.
    std::function<std::unique_ptr<Renderer>()> renderer_factory;
};

/// Server-wide counters; gauges are current values, the rest totals.
struct ServerStats {
    std::uint64_t sessions_opened = 0;
    int sessions_active = 0;  ///< admitted sessions (gauge)
    int streams_open = 0;     ///< Stream reactors alive, admitted or not (gauge)
    std::uint64_t frames_sent = 0;
    std::uint64_t poses_coalesced = 0;
    std::uint64_t frames_coalesced = 0;
    std::uint64_t frame_errors = 0;
    std::int64_t frames_buffered = 0;        ///< encoded frames held by all sessions' output slots (gauge)
    std::int64_t bytes_buffered = 0;         ///< their bytes (gauge)
    std::int64_t peak_session_buffered = 0;  ///< most frames one session ever held at once
    std::uint64_t streams_stalled = 0;       ///< streams cancelled by the stall watchdog
    std::uint64_t open_timeouts = 0;         ///< streams finished for sending no opening message in time
    std::uint64_t reads_delayed = 0;         ///< reads postponed by the pose-rate limit
    std::uint64_t out_of_memory = 0;         ///< sessions and loads refused for memory
    std::uint64_t streams_refused = 0;       ///< stream calls refused at ServerCore::max_streams
    int pooled_renderers = 0;                ///< idle renderers kept for unary renders (gauge)
};

/// The worker counts that 0 (auto) stands for, sized from the machine: `cores` (0: unknown,
/// taken as 1), the backend and the `devices` sessions are placed on (--gpus).
/// - render: CUDA kRenderWorkersPerGpu per device, so that several sessions' frames overlap on the GPU
///   (its stages of one frame leave it idle between kernels and during copies); CPU two (one
///   on one core): each render already spreads over --render-threads cores, and the second
///   lets a small viewer's render start beside a large one instead of behind it.
/// - encode: the cores the renders leave, at least kMinEncodeWorkers and at most
///   `max_sessions` per device (a session encodes one frame at a time, so more would idle). The
///   CPU backend's renders take every core (its simulated devices share them): it gets
///   kMinEncodeWorkers.
struct WorkerCounts {
    int render = 0, encode = 0;
};
inline constexpr int kRenderWorkersPerGpu = 4;
/// Two: a session encodes one frame at a time, so a large encode (PNG) of one session never
/// makes another session's frame wait for a worker.
inline constexpr int kMinEncodeWorkers = 2;
WorkerCounts auto_worker_counts(const std::string& backend, int cores, int max_sessions, int devices = 1);
/// What --help says 0 means, in the terms above.
std::string auto_worker_counts_help();

/// Stream calls the server keeps alive beyond its session slots: clients reconnecting, refused
/// or finishing, and calls that have not sent their opening message yet (each ended by the
/// open timeout). Far above what viewers need; it bounds what a flood of idle calls can hold
/// (measured: 3000 idle calls on one connection, +129 MB with the client's share).
inline constexpr int kStreamsAwaitingAdmission = 1024;

class StreamSession;

class ServerCore {
public:
    explicit ServerCore(ServerOptions options);
    ~ServerCore();

    const ServerOptions& options() const { return options_; }
    SceneRegistry& scenes() { return scenes_; }
    Admission& admission() { return admission_; }
    DevicePlacement& placement() { return placement_; }
    WorkerPool& render_pool() { return render_pool_; }
    WorkerPool& encode_pool() { return encode_pool_; }
    WorkerPool& admin_pool() { return admin_pool_; }

    /// OK, or UNAUTHENTICATED when a bearer token is configured and the call lacks it.
    grpc::Status authorize(const grpc::CallbackServerContext* context) const;
    /// A renderer for one session on `device` (a DevicePlacement::Seat's), on the configured
    /// backend; without one, on the first configured device. Slow on CUDA (allocations): call
    /// from a worker.
    std::unique_ptr<Renderer> make_session_renderer(int device) const;
    std::unique_ptr<Renderer> make_session_renderer() const { return make_session_renderer(options_.devices.front()); }

    /// Unary renders and stream sessions reuse renderers (on CUDA each holds arenas, streams
    /// and pinned buffers, slow to make, and the first frames grow the arenas): a renderer of
    /// the seat's device showing `scene`, taken from the pool when one of that device is idle,
    /// its inter-frame cache reset. When the scene does not fit on the device, the device's idle
    /// pooled renderers are dropped and the upload is tried once more. Call from a worker.
    std::unique_ptr<Renderer> acquire_renderer(const std::shared_ptr<const Scene>& scene,
                                               const DevicePlacement::Seat& seat);
    /// Returns a healthy renderer to the pool (at most render_workers are kept), where it keeps
    /// the scene resident on its device, so that the next session or unary call on that scene
    /// neither uploads it again nor grows new arenas. Call while the caller still holds its
    /// scene lease and seat: renderers of scenes being unloaded are dropped.
    void release_renderer(std::unique_ptr<Renderer> renderer, const std::shared_ptr<const Scene>& scene,
                          const DevicePlacement::Seat& seat);
    /// Makes a loaded scene resident before its first session, on backends whose renderers hold
    /// device memory (CUDA): an idle pooled renderer on each device (at most render_workers of
    /// them) uploads it and keeps it there, so that the first viewer does not wait for the upload
    /// (about 200 ms for the kit's 1.4 GB city on an H200). A device it does not fit on is
    /// skipped with a warning. Slow: call before listening, or from a worker.
    void prewarm(const std::string& scene_id);
    /// Drops the idle pooled renderers of the seat's device, freeing what they held there (a
    /// frame ran out of device memory: the client's retry must not find it still taken).
    /// True when there were any.
    bool drop_idle_renderers(const DevicePlacement::Seat& seat);

    /// Registers a new stream call, or refuses it (RESOURCE_EXHAUSTED "max-streams: ...") when
    /// max_streams() calls are alive already.
    grpc::Status add_stream(const std::shared_ptr<StreamSession>& session);
    /// Stream calls alive at once, admitted or not: every session slot plus
    /// kStreamsAwaitingAdmission. Each call costs buffers (about 20 KB on the server) until it
    /// ends, and a client may start thousands before the open timeout ends any of them.
    int max_streams() const;
    void remove_stream(StreamSession* session);
    std::vector<std::shared_ptr<StreamSession>> streams() const;

    struct Counters {
        std::atomic<std::uint64_t> sessions_opened{0}, frames_sent{0}, poses_coalesced{0}, frames_coalesced{0},
            frame_errors{0};
        std::atomic<std::int64_t> frames_buffered{0}, bytes_buffered{0}, peak_session_buffered{0};
        std::atomic<std::uint64_t> next_session_id{1};
        std::atomic<std::uint64_t> streams_stalled{0}, open_timeouts{0}, reads_delayed{0}, out_of_memory{0};
    };
    Counters& counters() { return counters_; }
    ServerStats stats() const;
    /// Stops the worker pools and the watchdog (after the gRPC server has shut down).
    void stop_workers();

private:
    void watchdog();
    void drop_pooled(const Scene* scene);
    /// Drops the idle pooled renderers `drop` accepts; true when there were any.
    template <typename Predicate>
    bool drop_pooled_if(Predicate&& drop);

    // The server's locks, and which may be held while taking which (no other nesting exists;
    // callbacks and destructors that take a lock run after the caller's lock is released):
    //   StreamSession::mutex_ -> Admission's, SceneRegistry's, DevicePlacement's and WorkerPool's
    //                            mutexes (admit, acquire_scene, place and post while handling a
    //                            request);
    //   pool_mutex_           -> SceneRegistry's mutex (release_renderer checks the scene),
    //                            DevicePlacement's (the pool's holds on scenes);
    // and taken alone: streams_mutex_, watchdog_mutex_, Server::mutex_. The SceneRegistry calls
    // its on_freed listener (drop_pooled, which takes pool_mutex_) outside its own lock.
    ServerOptions options_;
    SceneRegistry scenes_;
    Admission admission_;  // every device's sessions: placement_ counts them per device
    DevicePlacement placement_;
    Counters counters_;
    WorkerPool render_pool_;
    WorkerPool encode_pool_;
    WorkerPool admin_pool_;  ///< scene loads: slow, kept off the render workers
    mutable std::mutex streams_mutex_;
    std::set<std::shared_ptr<StreamSession>> streams_;
    std::atomic<std::uint64_t> streams_refused_{0};

    struct PooledRenderer {
        std::shared_ptr<const Scene> scene;
        std::string scene_id;
        int slot = 0;  // its device's position in placement_
        std::unique_ptr<Renderer> renderer;
    };
    mutable std::mutex pool_mutex_;
    std::vector<PooledRenderer> pool_;

    std::mutex watchdog_mutex_;
    std::condition_variable watchdog_wake_;
    bool watchdog_stop_ = false;
    std::thread watchdog_;
};

}  // namespace catgs::server
