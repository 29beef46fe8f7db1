#include "catgs/server/server_core.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstdint>
#include <limits>
#include <thread>

#include "catgs/error.hpp"
#include "catgs/server/stream_session.hpp"

namespace catgs::server {
namespace {

/// Compares without an early exit, so the time taken does not reveal how much of a guessed
/// token was right.
bool constant_time_equal(const std::string& a, const std::string& b) {
    unsigned char diff = a.size() == b.size() ? 0 : 1;
    const std::size_t n = std::max(a.size(), b.size());
    for (std::size_t i = 0; i < n; ++i) {
        const unsigned char x = i < a.size() ? static_cast<unsigned char>(a[i]) : 0;
        const unsigned char y = i < b.size() ? static_cast<unsigned char>(b[i]) : 0;
        diff |= static_cast<unsigned char>(x ^ y);
    }
    return diff == 0;
}

/// Cores the CUDA backend's render workers use between them: they mostly wait for the device.
constexpr int kCudaFeedingCores = 1;

/// --max-sessions on each of `devices`, in all; saturating, as --max-sessions may be as large as
/// an int holds.
int sessions_on_devices(int max_sessions, int devices) {
    const std::int64_t all = static_cast<std::int64_t>(max_sessions) * std::max(devices, 1);
    return static_cast<int>(std::min<std::int64_t>(all, std::numeric_limits<int>::max()));
}

/// Replaces 0 (auto) worker counts with auto_worker_counts, and logs what was chosen.
ServerOptions with_worker_counts(ServerOptions o) {
    if (o.render_workers > 0 && o.encode_workers > 0) return o;
    const int cores = static_cast<int>(std::thread::hardware_concurrency());
    const int devices = static_cast<int>(o.devices.size());
    const WorkerCounts counts = auto_worker_counts(o.backend, cores, o.limits.max_sessions, devices);
    const bool render_auto = o.render_workers <= 0, encode_auto = o.encode_workers <= 0;
    if (render_auto) o.render_workers = counts.render;
    if (encode_auto) o.encode_workers = counts.encode;
    spdlog::info("workers: {} render{}, {} encode{} ({} backend, {} device{}, {} cores)", o.render_workers,
                 render_auto ? " (auto)" : "", o.encode_workers, encode_auto ? " (auto)" : "", o.backend, devices,
                 devices == 1 ? "" : "s", cores);
    return o;
}

}  // namespace

WorkerCounts auto_worker_counts(const std::string& backend, int cores, int max_sessions, int devices) {
    cores = std::max(cores, 1);
    devices = std::max(devices, 1);
    WorkerCounts counts;
    int left = 0;  // cores the renders leave to encoding
    if (backend == "cuda") {
        counts.render = kRenderWorkersPerGpu * devices;
        left = cores - kCudaFeedingCores * devices;
    } else {
        counts.render = std::min(2, cores);
    }
    counts.encode = std::max(kMinEncodeWorkers, std::min(left, sessions_on_devices(max_sessions, devices)));
    return counts;
}

std::string auto_worker_counts_help() {
    return "0: auto, from the machine: render " + std::to_string(kRenderWorkersPerGpu) +
           " per GPU on CUDA (sessions' frames overlap on the GPU), 2 on the CPU backend (1 on one core); encode the "
           "cores left (CUDA: all but " +
           std::to_string(kCudaFeedingCores) + " per GPU, CPU: none), at least " + std::to_string(kMinEncodeWorkers) +
           ", at most --max-sessions times the devices";
}

ServerCore::ServerCore(ServerOptions options)
    : options_(with_worker_counts(std::move(options))),
      scenes_(options_.scene_root, options_.limits.max_scene_bytes),
      // --max-sessions is per device: the server admits that many on each, and placement_
      // refuses a device that is full.
      admission_(sessions_on_devices(options_.limits.max_sessions, static_cast<int>(options_.devices.size()))),
      placement_(options_.devices, options_.limits.max_sessions),
      render_pool_("render", options_.render_workers),
      encode_pool_("encode", options_.encode_workers),
      admin_pool_("scene-load", 1) {
    scenes_.set_on_freed([this](const Scene* scene) { drop_pooled(scene); });
    std::string devices;
    for (int d : options_.devices) devices += (devices.empty() ? "" : ", ") + std::to_string(d);
    spdlog::info("devices: {} ({} backend{}), at most {} sessions each", devices, options_.backend,
                 options_.backend == "cuda" || options_.devices.size() == 1 ? "" : ", simulated",
                 options_.limits.max_sessions);
    if (options_.limits.stall_timeout_ms > 0 || options_.limits.open_timeout_ms > 0)
        watchdog_ = std::thread([this] { watchdog(); });
}

ServerCore::~ServerCore() {
    stop_workers();
    scenes_.set_on_freed(nullptr);
}

grpc::Status ServerCore::authorize(const grpc::CallbackServerContext* context) const {
    if (options_.bearer_token.empty()) return grpc::Status::OK;
    const auto& metadata = context->client_metadata();
    auto it = metadata.find("authorization");
    static const std::string kPrefix = "Bearer ";
    if (it != metadata.end()) {
        const std::string value(it->second.data(), it->second.size());
        if (value.rfind(kPrefix, 0) == 0 && constant_time_equal(value.substr(kPrefix.size()), options_.bearer_token))
            return grpc::Status::OK;
        return {grpc::StatusCode::UNAUTHENTICATED, "authorization: wrong bearer token"};
    }
    return {grpc::StatusCode::UNAUTHENTICATED, "authorization: missing metadata 'authorization: Bearer <token>'"};
}

std::unique_ptr<Renderer> ServerCore::make_session_renderer(int device) const {
    if (options_.renderer_factory) return options_.renderer_factory();
    return make_renderer(options_.backend, parse_precision(options_.precision), options_.render_threads, device);
}

std::unique_ptr<Renderer> ServerCore::acquire_renderer(const std::shared_ptr<const Scene>& scene,
                                                       const DevicePlacement::Seat& seat) {
    std::unique_ptr<Renderer> renderer;
    bool holds_another_scene = false;  // taken from the pool, still showing its former scene
    {
        std::lock_guard lock(pool_mutex_);
        // Of the seat's device: one already showing this scene (no upload), else any idle one.
        const auto here = [&](const PooledRenderer& p) { return p.slot == seat.slot(); };
        auto it = std::find_if(pool_.begin(), pool_.end(),
                               [&](const PooledRenderer& p) { return here(p) && p.scene == scene; });
        if (it == pool_.end()) it = std::find_if(pool_.begin(), pool_.end(), here);
        if (it != pool_.end()) {
            renderer = std::move(it->renderer);
            const bool same = it->scene == scene;
            // The seat holds the scene on this device meanwhile: its residency does not lapse.
            placement_.release_pooled(it->slot, it->scene_id);
            pool_.erase(it);
            if (same) {
                renderer->reset_cache();
                return renderer;
            }
            holds_another_scene = true;
        }
    }
    if (!renderer) renderer = make_session_renderer(seat.device());
    try {
        renderer->set_scene(scene);
    } catch (const OutOfMemoryError&) {
        // Idle renderers hold their scenes and arenas on the device: they yield to a session,
        // and so does the one taken from the pool (it still holds its former scene).
        const bool dropped = drop_idle_renderers(seat);
        if (!dropped && !holds_another_scene) throw;
        renderer.reset();
        spdlog::info("device {}: idle pooled renderers let go of their memory for scene {}", seat.device(),
                     seat.scene_id());
        renderer = make_session_renderer(seat.device());
        renderer->set_scene(scene);
    }
    return renderer;
}

void ServerCore::release_renderer(std::unique_ptr<Renderer> renderer, const std::shared_ptr<const Scene>& scene,
                                  const DevicePlacement::Seat& seat) {
    const std::string& scene_id = seat.scene_id();
    if (!renderer) return;
    std::unique_ptr<Renderer> surplus;  // destroyed outside the lock
    std::lock_guard lock(pool_mutex_);
    // A scene being unloaded must not be kept alive by an idle renderer. Checked under
    // pool_mutex_: an unload after the check waits in drop_pooled for this lock.
    SceneSummary summary;
    if (!scenes_.get(scene_id, &summary).ok() || summary.unloading ||
        static_cast<int>(pool_.size()) >= std::max(1, options_.render_workers)) {
        surplus = std::move(renderer);
        return;
    }
    placement_.hold_pooled(seat.slot(), scene_id);
    pool_.push_back({scene, scene_id, seat.slot(), std::move(renderer)});
}

template <typename Predicate>
bool ServerCore::drop_pooled_if(Predicate&& drop) {
    std::vector<PooledRenderer> dropped;  // destroyed outside the lock
    std::lock_guard lock(pool_mutex_);
    for (auto it = pool_.begin(); it != pool_.end();) {
        if (drop(*it)) {
            placement_.release_pooled(it->slot, it->scene_id);
            dropped.push_back(std::move(*it));
            it = pool_.erase(it);
        } else {
            ++it;
        }
    }
    return !dropped.empty();
}

void ServerCore::prewarm(const std::string& scene_id) {
    // The CPU backend shares the host's copy of the scene: nothing to upload (a renderer
    // factory's renderers, a test's simulated device, may hold device memory).
    if (!options_.prewarm || (options_.backend == "cpu" && !options_.renderer_factory)) return;
    std::unique_ptr<SceneRegistry::Lease> lease;
    if (!acquire_scene(scenes_, scene_id, "prewarm", &lease).ok()) return;
    // Seats held at once: each goes to another device (the one with the fewest sessions).
    const std::size_t renderers =
        std::min(placement_.devices().size(), static_cast<std::size_t>(std::max(1, options_.render_workers)));
    std::vector<std::unique_ptr<DevicePlacement::Seat>> seats;
    for (std::size_t i = 0; i < renderers; ++i) {
        std::unique_ptr<DevicePlacement::Seat> seat;
        if (!placement_.place(scene_id, &seat).ok()) break;
        seats.push_back(std::move(seat));
    }
    for (const auto& seat : seats) {
        try {
            // A new renderer, not a pooled one: that would let go of the scene it holds (another
            // start-up scene's).
            std::unique_ptr<Renderer> renderer = make_session_renderer(seat->device());
            renderer->set_scene(lease->scene());
            release_renderer(std::move(renderer), lease->scene(), *seat);
        } catch (const std::exception& e) {
            spdlog::warn("scene {} not made resident on device {} before its first session: {}", scene_id,
                         seat->device(), e.what());
        }
    }
}

bool ServerCore::drop_idle_renderers(const DevicePlacement::Seat& seat) {
    return drop_pooled_if([&](const PooledRenderer& p) { return p.slot == seat.slot(); });
}

void ServerCore::drop_pooled(const Scene* scene) {
    drop_pooled_if([scene](const PooledRenderer& p) { return p.scene.get() == scene; });
}

// The watchdog: a stream whose frame has sat in gRPC's hands longer than the stall timeout
// belongs to a client that stopped reading, one without its opening message after the open
// timeout to a client that never meant to open; ending them frees their resources. It wakes
// every 1/20 of the shorter timeout, so each fires at most 5% late (plus scheduling).
void ServerCore::watchdog() {
    using std::chrono::milliseconds;
    const milliseconds stall(options_.limits.stall_timeout_ms), open(options_.limits.open_timeout_ms);
    const milliseconds shortest = stall.count() > 0 && open.count() > 0 ? std::min(stall, open)
                                  : stall.count() > 0                   ? stall
                                                                        : open;
    const auto period = std::clamp(shortest / 20, milliseconds(5), milliseconds(1000));
    std::unique_lock lock(watchdog_mutex_);
    while (!watchdog_wake_.wait_for(lock, period, [this] { return watchdog_stop_; })) {
        lock.unlock();
        const auto now = std::chrono::steady_clock::now();
        for (const auto& session : streams()) {
            // Each counts itself (ServerStats) before its status reaches the client.
            if (stall.count() > 0) session->cancel_if_stalled(now, stall);
            if (open.count() > 0) session->finish_if_not_opened(now, open);
        }
        lock.lock();
    }
}

int ServerCore::max_streams() const {
    const std::int64_t all = static_cast<std::int64_t>(admission_.max_sessions()) + kStreamsAwaitingAdmission;
    return static_cast<int>(std::min<std::int64_t>(all, std::numeric_limits<int>::max()));
}

grpc::Status ServerCore::add_stream(const std::shared_ptr<StreamSession>& session) {
    std::lock_guard lock(streams_mutex_);
    const int limit = max_streams();
    if (static_cast<int>(streams_.size()) >= limit) {
        streams_refused_++;
        return {grpc::StatusCode::RESOURCE_EXHAUSTED, "max-streams: " + std::to_string(streams_.size()) +
                                                          " stream calls are open, the most this server " + "takes (" +
                                                          std::to_string(limit) + "); finish idle ones or retry later"};
    }
    streams_.insert(session);
    return grpc::Status::OK;
}

void ServerCore::remove_stream(StreamSession* session) {
    std::shared_ptr<StreamSession> removed;  // released outside the lock
    std::lock_guard lock(streams_mutex_);
    for (auto it = streams_.begin(); it != streams_.end(); ++it)
        if (it->get() == session) {
            removed = *it;
            streams_.erase(it);
            break;
        }
}

std::vector<std::shared_ptr<StreamSession>> ServerCore::streams() const {
    std::lock_guard lock(streams_mutex_);
    return {streams_.begin(), streams_.end()};
}

ServerStats ServerCore::stats() const {
    ServerStats s;
    s.sessions_opened = counters_.sessions_opened;
    s.sessions_active = admission_.active();
    {
        std::lock_guard lock(streams_mutex_);
        s.streams_open = static_cast<int>(streams_.size());
    }
    s.frames_sent = counters_.frames_sent;
    s.poses_coalesced = counters_.poses_coalesced;
    s.frames_coalesced = counters_.frames_coalesced;
    s.frame_errors = counters_.frame_errors;
    s.frames_buffered = counters_.frames_buffered;
    s.bytes_buffered = counters_.bytes_buffered;
    s.peak_session_buffered = counters_.peak_session_buffered;
    s.streams_stalled = counters_.streams_stalled;
    s.streams_refused = streams_refused_;
    s.open_timeouts = counters_.open_timeouts;
    s.reads_delayed = counters_.reads_delayed;
    s.out_of_memory = counters_.out_of_memory;
    {
        std::lock_guard lock(pool_mutex_);
        s.pooled_renderers = static_cast<int>(pool_.size());
    }
    return s;
}

void ServerCore::stop_workers() {
    admin_pool_.stop();
    render_pool_.stop();
    encode_pool_.stop();
    {
        std::lock_guard lock(watchdog_mutex_);
        watchdog_stop_ = true;
    }
    watchdog_wake_.notify_all();
    if (watchdog_.joinable() && watchdog_.get_id() != std::this_thread::get_id()) watchdog_.join();
    std::vector<PooledRenderer> pool;
    {
        std::lock_guard lock(pool_mutex_);
        pool.swap(pool_);
        for (const PooledRenderer& p : pool) placement_.release_pooled(p.slot, p.scene_id);
    }
}

}  // namespace catgs::server
