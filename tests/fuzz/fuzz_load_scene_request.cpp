// libFuzzer target: SceneService.LoadScene from bytes. The bytes are parsed as a
// catgs.v1.LoadSceneRequest and handed to SceneRegistry::load as the service does (an
// untrusted client: paths are resolved under the scene root). The scene root holds a tiny
// valid PLY and .splat, a bad PLY, a subfolder and symbolic links that point out of it
// (to "/" and to ".."), so that containment, id derivation and error rewriting are searched.
//
// Allocation cap: the registry gets a 1 MiB scene budget, and builtin: sources are only passed
// on when they name an explicit gaussians=N (the registry refuses those over budget before
// generating anything; without the key the default million-Gaussian city would be built).

#include <sys/stat.h>
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>

#include <spdlog/spdlog.h>

#include "catgs/builtin_spec.hpp"
#include "catgs/error.hpp"
#include "catgs/server/scene_registry.hpp"
#include "catgs/v1/catgs.pb.h"
#include "fuzz_util.hpp"

namespace {

using catgs::fuzz::require;

/// A fixed path, so that the seed corpus can name files through the links; parallel fuzz
/// jobs create the same contents (atomically, by rename).
const std::string kRoot = "/tmp/catgs-fuzz-scene-root";

void put_file(const std::string& name, const std::string& bytes) {
    const std::string tmp = kRoot + "/" + name + ".tmp" + std::to_string(::getpid());
    std::ofstream(tmp, std::ios::binary).write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    if (std::rename(tmp.c_str(), (kRoot + "/" + name).c_str()) != 0) std::abort();
}

std::string tiny_ply(bool bad) {
    std::string h = "ply\nformat ascii 1.0\nelement vertex 1\n";
    for (const char* p : {"x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2",
                          "rot_0", "rot_1", "rot_2", "rot_3"})
        h += std::string("property float ") + p + "\n";
    return h + "end_header\n" + (bad ? "0 0 0 0 0 0 nan 0 0 0 1 0 0 0\n" : "0 0 0 0.5 0.5 0.5 2 -1 -1 -1 1 0 0 0\n");
}

std::string tiny_splat() {
    std::string s(32, '\0');
    const float position_scale[6] = {0, 0, 0, 0.1f, 0.1f, 0.1f};
    std::memcpy(s.data(), position_scale, sizeof position_scale);
    const unsigned char rgba_quaternion[8] = {200, 100, 50, 255, 255, 128, 128, 128};
    std::memcpy(s.data() + 24, rgba_quaternion, sizeof rgba_quaternion);
    return s;
}

void make_root() {
    ::mkdir(kRoot.c_str(), 0755);
    ::mkdir((kRoot + "/sub").c_str(), 0755);
    put_file("tiny.ply", tiny_ply(false));
    put_file("bad.ply", tiny_ply(true));
    put_file("tiny.splat", tiny_splat());
    put_file("sub/tiny.ply", tiny_ply(false));
    ::symlink("/", (kRoot + "/slash").c_str());
    ::symlink("..", (kRoot + "/up").c_str());
    ::symlink("tiny.ply", (kRoot + "/link.ply").c_str());
}

/// Would the registry generate a city for this source before checking the budget?
bool builds_a_city(const std::string& source) {
    if (source.rfind("builtin:", 0) != 0) return false;
    try {
        for (const auto& [key, value] : catgs::detail::builtin_params(source, {"gaussians", "seed"}))
            if (key == "gaussians") return false;
    } catch (const catgs::Error&) {
        return false;  // refused before loading
    }
    return true;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    static const std::string root = [] {
        spdlog::set_level(spdlog::level::off);  // the registry logs every load
        make_root();
        return std::filesystem::canonical(kRoot).string();
    }();
    if (size > 4096) return -1;
    catgs::v1::LoadSceneRequest request;
    if (!request.ParseFromArray(data, static_cast<int>(size))) return -1;
    if (builds_a_city(request.source())) return -1;

    catgs::server::SceneRegistry registry(kRoot, std::uint64_t{1} << 20);
    catgs::server::SceneSummary summary;
    const grpc::Status status =
        registry.load(request.scene_id(), request.source(), request.drop_invalid(), false, &summary);
    if (!status.ok()) {
        require(!status.error_message().empty(), "empty error message");
        const auto code = status.error_code();
        require(code == grpc::StatusCode::INVALID_ARGUMENT || code == grpc::StatusCode::RESOURCE_EXHAUSTED,
                "unexpected status code " + std::to_string(code) + ": " + status.error_message());
        return 0;
    }
    require(catgs::server::valid_scene_id(summary.id), "loaded under an invalid id '" + summary.id + "'");
    require(summary.gaussians > 0, "loaded an empty scene");
    require(request.source().rfind("builtin:", 0) != 0, "a builtin city within a 1 MiB budget");
    std::string absolute;
    require(registry.resolve_path(request.source(), &absolute).ok(), "loaded a path that does not resolve");
    require(absolute.rfind(root + "/", 0) == 0, "loaded '" + absolute + "', outside the scene root");
    bool freed = false;
    require(registry.unload(summary.id, nullptr, &freed).ok() && freed, "unload failed");
    return 0;
}
