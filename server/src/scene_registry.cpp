#include "catgs/server/scene_registry.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cctype>
#include <filesystem>

#include "catgs/builtin_spec.hpp"
#include "catgs/error.hpp"
#include "catgs/regular_file.hpp"
#include "catgs/scene_io.hpp"
#include "catgs/server/request_validation.hpp"

namespace catgs::server {

namespace fs = std::filesystem;

namespace {

constexpr std::size_t kMaxSceneIdLength = 128;
/// Host bytes per Gaussian of a degree-3 scene (position 3, scale 3, rotation 4, opacity 1,
/// 48 SH floats): the upper bound used to refuse an over-limit load before allocating it.
constexpr std::uint64_t kMaxBytesPerGaussian = scene_bytes_per_gaussian(3);

/// An id the client sent, for a message that log lines repeat: control bytes escaped (a
/// newline would forge a line), and cut short (ids that long are never loaded).
std::string quoted_id(const std::string& id) {
    std::string out = "'";
    for (std::size_t i = 0; i < id.size() && i <= kMaxSceneIdLength; ++i) {
        const auto byte = static_cast<unsigned char>(id[i]);
        if (i == kMaxSceneIdLength) {
            out += "...";
        } else if (is_control_byte(byte)) {
            static constexpr char kHex[] = "0123456789abcdef";
            out += std::string("\\x") + kHex[byte >> 4] + kHex[byte & 15];
        } else {
            out += static_cast<char>(byte);
        }
    }
    return out + "'";
}

grpc::Status no_such_scene(const std::string& id) {
    return {grpc::StatusCode::NOT_FOUND, "scene_id " + quoted_id(id) + ": no such scene"};
}

/// A loader's message names the file by the path the server opened; clients get the source
/// they asked for.
std::string as_source(std::string message, const std::string& path, const std::string& source) {
    if (path == source) return message;
    // Searching on after each replacement: the source may contain the path (a link in the root
    // back to it), and searching from the start again would never end.
    for (std::size_t at = 0; (at = message.find(path, at)) != std::string::npos; at += source.size())
        message.replace(at, path.size(), source);
    return message;
}

SceneSummary summarize(const std::string& id, const std::string& source, const Scene& scene) {
    SceneSummary s;
    s.id = id;
    s.source = source;
    s.gaussians = scene.count();
    s.sh_degree = scene.sh_degree;
    s.bounds = scene.bounds;
    s.host_bytes = scene.bytes();
    return s;
}

bool is_builtin(const std::string& source) {
    return source.rfind("builtin:", 0) == 0;
}

}  // namespace

struct SceneRegistry::Lease::State {
    struct Entry {
        std::shared_ptr<const Scene> scene;
        SceneSummary summary;  // sessions and unloading kept current
    };
    mutable std::mutex mutex;  // a leaf: on_freed runs outside it (lock order: server_core.hpp)
    std::map<std::string, Entry> scenes;
    std::uint64_t bytes = 0;  // host bytes of every loaded scene
    std::function<void(const Scene*)> on_freed;

    void release(const std::string& id) {
        std::shared_ptr<const Scene> freed;  // destroyed outside the lock
        {
            std::lock_guard lock(mutex);
            auto it = scenes.find(id);
            if (it == scenes.end()) return;
            if (it->second.summary.sessions > 0) --it->second.summary.sessions;
            if (it->second.summary.unloading && it->second.summary.sessions == 0) {
                spdlog::info("scene {} freed (last session closed)", id);
                bytes -= it->second.summary.host_bytes;
                freed = std::move(it->second.scene);
                scenes.erase(it);
            }
        }
        if (freed && on_freed) on_freed(freed.get());
    }
};

SceneRegistry::Lease::Lease(std::shared_ptr<State> state, std::string id, std::shared_ptr<const Scene> scene)
    : state_(std::move(state)), id_(std::move(id)), scene_(std::move(scene)) {}

SceneRegistry::Lease::~Lease() {
    scene_.reset();
    state_->release(id_);
}

SceneRegistry::SceneRegistry(std::string scene_root, std::uint64_t max_scene_bytes)
    : state_(std::make_shared<Lease::State>()), scene_root_(std::move(scene_root)), max_scene_bytes_(max_scene_bytes) {}

bool valid_scene_id(const std::string& id) {
    if (id.empty() || id.size() > kMaxSceneIdLength || id == "." || id == "..") return false;
    for (char c : id)
        if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '_' || c == '-')) return false;
    return true;
}

std::string default_scene_id(const std::string& source) {
    if (is_builtin(source)) {
        try {
            return detail::builtin_name(source);
        } catch (const std::exception&) {
            return "builtin";
        }
    }
    return fs::path(source).stem().string();
}

grpc::Status SceneRegistry::resolve_path(const std::string& relative, std::string* absolute) const {
    if (scene_root_.empty())
        return {grpc::StatusCode::INVALID_ARGUMENT,
                "source: this server has no scene root (--scene-root), only builtin: scenes can be loaded"};
    const fs::path rel(relative);
    if (relative.empty() || rel.is_absolute())
        return {grpc::StatusCode::INVALID_ARGUMENT,
                "source '" + relative + "': expected a path relative to the scene root or a builtin: generator"};
    std::error_code ec;
    const fs::path root = fs::canonical(scene_root_, ec);
    if (ec) return {grpc::StatusCode::INTERNAL, "scene root '" + scene_root_ + "' is not accessible: " + ec.message()};
    // canonical() resolves "..", "." and symbolic links, so the containment test below sees
    // where the file really is.
    const fs::path full = fs::canonical(root / rel, ec);
    if (ec) return {grpc::StatusCode::INVALID_ARGUMENT, "source '" + relative + "': no such file under the scene root"};
    if (!is_within(root, full))
        return {grpc::StatusCode::INVALID_ARGUMENT, "source '" + relative + "': path leaves the scene root"};
    if (!fs::is_regular_file(full, ec))
        return {grpc::StatusCode::INVALID_ARGUMENT, "source '" + relative + "': not a regular file"};
    *absolute = full.string();
    return grpc::Status::OK;
}

grpc::Status SceneRegistry::load(const std::string& requested_id, const std::string& source, bool drop_invalid,
                                 bool trusted, SceneSummary* out) {
    if (source.empty()) return {grpc::StatusCode::INVALID_ARGUMENT, "source: empty"};
    // The file system would see only the part before a NUL byte.
    if (source.find('\0') != std::string::npos)
        return {grpc::StatusCode::INVALID_ARGUMENT, "source: contains a NUL byte"};
    const std::string id = requested_id.empty() ? default_scene_id(source) : requested_id;
    if (id == "." || id == "..")
        // Ids end up in paths and URLs of tools and logs, where these two name directories.
        return {grpc::StatusCode::INVALID_ARGUMENT,
                "scene_id '" + id + "': '.' and '..' are not scene ids (they name directories); choose another id"};
    if (!valid_scene_id(id))
        return {grpc::StatusCode::INVALID_ARGUMENT,
                "scene_id " + quoted_id(id) + ": expected 1..128 characters of letters, digits, '.', '_' or '-'"};
    {
        std::lock_guard lock(state_->mutex);
        if (grpc::Status taken = id_taken_locked(id); !taken.ok()) return taken;
    }

    std::string path = source;
    std::uint64_t estimate = 0;  // upper bound on host bytes, checked before loading
    if (is_builtin(source)) {
        try {
            for (const auto& [key, value] : detail::builtin_params(source, {"gaussians", "seed"}))
                if (key == "gaussians") estimate = detail::spec_integer(source, key, value) * kMaxBytesPerGaussian;
        } catch (const Error& e) {
            return {grpc::StatusCode::INVALID_ARGUMENT, std::string("source: ") + e.what()};
        }
    } else {
        if (!trusted) {
            grpc::Status resolved = resolve_path(source, &path);
            if (!resolved.ok()) return resolved;
        }
        std::error_code ec;
        // A lower bound from the file size: a .splat record (32 bytes) becomes 59 floats at most
        // and at least 14 floats (56 bytes), a PLY record never shrinks below a quarter. This
        // screens out hopeless files before allocating; the exact check follows the load.
        const auto size = fs::file_size(path, ec);
        if (!ec) estimate = size / 4;
    }
    if (max_scene_bytes_ > 0) {
        std::lock_guard lock(state_->mutex);
        if (state_->bytes + estimate > max_scene_bytes_)
            return {grpc::StatusCode::RESOURCE_EXHAUSTED,
                    "max-scene-bytes: loading '" + source + "' would exceed the limit of " +
                        std::to_string(max_scene_bytes_) + " bytes (" + std::to_string(state_->bytes) + " in use)"};
    }

    std::shared_ptr<const Scene> scene;
    try {
        LoadOptions options;
        options.drop_invalid = drop_invalid;
        // The files a scene names beside itself (an unbundled SOG's textures) stay under the
        // root too: a link there must not reach what resolve_path refuses to open directly.
        if (!trusted) options.scene_root = scene_root_;
        // A compressed file (.spz, SOG, compressed PLY) may declare far more Gaussians than
        // its size suggests: the readers refuse a count the memory left cannot hold at the
        // file's SH degree before they allocate for it (at degree 0's cost a degree-3 file
        // could allocate 4.2 times the limit before the check below measured it).
        if (max_scene_bytes_ > 0) {
            std::lock_guard lock(state_->mutex);
            options.max_scene_bytes = max_scene_bytes_ > state_->bytes ? max_scene_bytes_ - state_->bytes : 0;
        }
        scene = std::make_shared<const Scene>(load_scene(path, options));
    } catch (const LimitError& e) {
        // The file may be valid: the memory left refused it, as the checks around the load do.
        return {grpc::StatusCode::RESOURCE_EXHAUSTED,
                "max-scene-bytes: loading '" + source + "' would exceed the limit of " +
                    std::to_string(max_scene_bytes_) + " bytes: " + as_source(e.what(), path, source)};
    } catch (const Error& e) {
        return {grpc::StatusCode::INVALID_ARGUMENT, "source: " + as_source(e.what(), path, source)};
    } catch (const std::bad_alloc&) {
        return {grpc::StatusCode::RESOURCE_EXHAUSTED, "source '" + source + "': out of memory while loading"};
    } catch (const std::exception& e) {
        // Not a bad input we know of: still an answer, never an exception into the worker.
        return {grpc::StatusCode::INTERNAL, "source '" + source + "': loading failed: " + e.what()};
    }
    if (scene->count() == 0) return {grpc::StatusCode::INVALID_ARGUMENT, "source '" + source + "': the scene is empty"};

    SceneSummary summary = summarize(id, source, *scene);
    std::lock_guard lock(state_->mutex);
    if (grpc::Status taken = id_taken_locked(id); !taken.ok()) return taken;
    if (max_scene_bytes_ > 0 && state_->bytes + summary.host_bytes > max_scene_bytes_)
        return {grpc::StatusCode::RESOURCE_EXHAUSTED, "max-scene-bytes: scene '" + source + "' needs " +
                                                          std::to_string(summary.host_bytes) + " bytes; the limit is " +
                                                          std::to_string(max_scene_bytes_) + " (" +
                                                          std::to_string(state_->bytes) + " in use)"};
    state_->bytes += summary.host_bytes;
    state_->scenes.emplace(id, Lease::State::Entry{std::move(scene), summary});
    spdlog::info("scene {} loaded from {}: {} Gaussians, SH degree {}, {:.1f} MB", id, source, summary.gaussians,
                 summary.sh_degree, summary.host_bytes / 1e6);
    if (out) *out = summary;
    return grpc::Status::OK;
}

grpc::Status SceneRegistry::acquire(const std::string& id, std::unique_ptr<Lease>* out) {
    std::lock_guard lock(state_->mutex);
    auto it = state_->scenes.find(id);
    if (it == state_->scenes.end()) return no_such_scene(id);
    if (it->second.summary.unloading)
        return {grpc::StatusCode::FAILED_PRECONDITION, "scene_id '" + id + "': the scene is being unloaded"};
    ++it->second.summary.sessions;
    out->reset(new Lease(state_, id, it->second.scene));
    return grpc::Status::OK;
}

grpc::Status acquire_scene(SceneRegistry& registry, const std::string& id, const std::string& prefix,
                           std::unique_ptr<SceneRegistry::Lease>* out) {
    grpc::Status status = registry.acquire(id, out);
    if (status.error_code() == grpc::StatusCode::NOT_FOUND)
        return {grpc::StatusCode::INVALID_ARGUMENT, prefix + "." + status.error_message()};
    if (!status.ok()) return {status.error_code(), prefix + "." + status.error_message()};
    return status;
}

grpc::Status SceneRegistry::unload(const std::string& id, SceneSummary* out, bool* freed) {
    std::shared_ptr<const Scene> to_free;  // destroyed outside the lock
    std::shared_ptr<const Scene> scene;    // the listener hears of it at once, freed or not
    {
        std::lock_guard lock(state_->mutex);
        auto it = state_->scenes.find(id);
        if (it == state_->scenes.end()) return no_such_scene(id);
        it->second.summary.unloading = true;
        scene = it->second.scene;
        if (out) *out = it->second.summary;
        *freed = it->second.summary.sessions == 0;
        if (*freed) {
            state_->bytes -= it->second.summary.host_bytes;
            to_free = std::move(it->second.scene);
            state_->scenes.erase(it);
            spdlog::info("scene {} unloaded", id);
        } else {
            spdlog::info("scene {} unloading: freed when its {} session(s) close", id, it->second.summary.sessions);
        }
    }
    if (state_->on_freed && (to_free || scene)) state_->on_freed(to_free ? to_free.get() : scene.get());
    return grpc::Status::OK;
}

void SceneRegistry::set_on_freed(std::function<void(const Scene*)> listener) {
    std::lock_guard lock(state_->mutex);
    state_->on_freed = std::move(listener);
}

// state_->mutex held.
grpc::Status SceneRegistry::id_taken_locked(const std::string& id) const {
    auto it = state_->scenes.find(id);
    if (it == state_->scenes.end()) return grpc::Status::OK;
    if (it->second.summary.unloading)
        return {grpc::StatusCode::ALREADY_EXISTS,
                "scene_id '" + id + "' is still unloading (freed when its " +
                    std::to_string(it->second.summary.sessions) +
                    " session(s) close); load it again after that or under another id"};
    return {grpc::StatusCode::ALREADY_EXISTS, "scene_id '" + id + "' is already loaded"};
}

grpc::Status SceneRegistry::get(const std::string& id, SceneSummary* out) const {
    std::lock_guard lock(state_->mutex);
    auto it = state_->scenes.find(id);
    if (it == state_->scenes.end()) return no_such_scene(id);
    *out = it->second.summary;
    return grpc::Status::OK;
}

std::vector<SceneSummary> SceneRegistry::list() const {
    std::lock_guard lock(state_->mutex);
    std::vector<SceneSummary> all;
    for (const auto& [id, entry] : state_->scenes) all.push_back(entry.summary);
    return all;
}

}  // namespace catgs::server
