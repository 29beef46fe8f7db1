// The scenes a server holds. Each scene is loaded once and shared (read-only) by every
// session that renders it, through a Lease that counts the sessions.
//
// Unload policy: UnloadScene marks the scene UNLOADING; new sessions are refused with
// FAILED_PRECONDITION; the scene is freed when the last lease is released (at once when no
// session uses it). This never blocks the caller and never pulls a scene from under an open
// stream.
#pragma once

#include <grpcpp/support/status.h>

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "catgs/scene.hpp"

namespace catgs::server {

struct SceneSummary {
    std::string id;
    std::string source;
    std::uint64_t gaussians = 0;
    int sh_degree = 0;
    Bounds bounds;
    std::uint64_t host_bytes = 0;
    std::uint32_t sessions = 0;
    bool unloading = false;
};

class SceneRegistry {
public:
    /// scene_root: directory that LoadScene paths are resolved in (empty: file loads refused).
    /// max_scene_bytes: the sum of host bytes of all loaded scenes may not exceed it (0: no limit).
    SceneRegistry(std::string scene_root, std::uint64_t max_scene_bytes);

    /// A session's hold on a scene; the scene stays loaded while any lease exists.
    class Lease {
    public:
        ~Lease();
        Lease(const Lease&) = delete;
        Lease& operator=(const Lease&) = delete;
        const std::shared_ptr<const Scene>& scene() const { return scene_; }

    private:
        friend class SceneRegistry;
        struct State;
        Lease(std::shared_ptr<State> state, std::string id, std::shared_ptr<const Scene> scene);
        std::shared_ptr<State> state_;
        std::string id_;
        std::shared_ptr<const Scene> scene_;
    };

    /// Loads `source` (a path under the scene root, or builtin:...) as `id` (empty: derived).
    /// `trusted` sources (the server's own command line) may be any path.
    /// Slow for big scenes: call from a worker thread, never from a gRPC reaction.
    grpc::Status load(const std::string& id, const std::string& source, bool drop_invalid, bool trusted,
                      SceneSummary* out);
    grpc::Status acquire(const std::string& id, std::unique_ptr<Lease>* out);
    grpc::Status unload(const std::string& id, SceneSummary* out, bool* freed);
    grpc::Status get(const std::string& id, SceneSummary* out) const;
    std::vector<SceneSummary> list() const;
    /// Called (outside the registry's lock) when a scene is unloaded (it accepts no more
    /// sessions, freed or not) and again when it is freed, so that holders of extra references
    /// (the server's renderer pool) can let it go. Set before serving.
    void set_on_freed(std::function<void(const Scene*)> listener);

    /// Resolves a client path against the scene root; INVALID_ARGUMENT when it is absolute,
    /// leaves the root (.., symbolic links) or does not exist. Public for tests.
    grpc::Status resolve_path(const std::string& relative, std::string* absolute) const;

private:
    grpc::Status id_taken_locked(const std::string& id) const;
    std::shared_ptr<Lease::State> state_;
    std::string scene_root_;
    std::uint64_t max_scene_bytes_;
};

/// acquire() for a session's opening message: an unknown scene is a bad request there
/// (INVALID_ARGUMENT naming "<prefix>.scene_id"), not a missing resource.
grpc::Status acquire_scene(SceneRegistry& registry, const std::string& id, const std::string& prefix,
                           std::unique_ptr<SceneRegistry::Lease>* out);

/// The id LoadScene uses when none is given: the file stem, or the generator's name.
std::string default_scene_id(const std::string& source);
/// Ids are 1..128 characters of [A-Za-z0-9._-], other than "." and "..".
bool valid_scene_id(const std::string& id);

}  // namespace catgs::server
