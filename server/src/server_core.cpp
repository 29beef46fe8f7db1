#include "catgs/server/server_core.hpp"

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

}  // namespace

ServerCore::ServerCore(ServerOptions options)
    : options_(std::move(options)),
      scenes_(options_.scene_root, options_.limits.max_scene_bytes),
      admission_(options_.limits.max_sessions),
      render_pool_("render", options_.render_workers),
      encode_pool_("encode", options_.encode_workers),
      admin_pool_("scene-load", 1) {}

ServerCore::~ServerCore() { stop_workers(); }

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

std::unique_ptr<Renderer> ServerCore::make_session_renderer() const {
    return make_renderer(options_.backend, parse_precision(options_.precision), options_.render_threads);
}

void ServerCore::add_stream(const std::shared_ptr<StreamSession>& session) {
    std::lock_guard lock(streams_mutex_);
    streams_.insert(session);
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
    return s;
}

void ServerCore::stop_workers() {
    admin_pool_.stop();
    render_pool_.stop();
    encode_pool_.stop();
}

}  // namespace catgs::server
