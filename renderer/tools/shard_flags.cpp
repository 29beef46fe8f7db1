#include "shard_flags.hpp"

#include <vector>

#include "catgs/device_list.hpp"
#include "catgs/error.hpp"
#include "catgs/shard_plan.hpp"

namespace catgs::cli {
namespace {

/// The CUDA devices --shard-devices names; the CPU backend renders every shard on the host.
std::vector<int> shard_devices(const ShardFlags& f, const std::string& backend) {
    if (backend != "cuda") return {0};
    return parse_device_list("--shard-devices", f.devices, device_count(backend), 1);
}

std::string join(const std::vector<int>& values) {
    std::string text;
    for (int v : values) text += (text.empty() ? "" : ", ") + std::to_string(v);
    return text;
}

}  // namespace

void add_shard_flags(CLI::App& app, ShardFlags& f) {
    app.add_option("--shards", f.shards,
                   "render each frame as K spatial shards of the scene, one renderer each, composited front to back "
                   "(docs/sharding.md)")
        ->capture_default_str()
        ->check(CLI::Range(1, kMaxShards));
    app.add_option("--shard-devices", f.devices,
                   "CUDA devices the shards render on, shard i on the (i mod n)-th: all, a count N, or a list (0,2); "
                   "several render at once")
        ->capture_default_str();
    app.add_option("--composite", f.composite,
                   "where the shards' partials are composited: auto (CUDA: on the first shard device; CPU: the "
                   "host), device, or host")
        ->capture_default_str()
        ->check(CLI::IsMember({"auto", "device", "host"}));
}

std::unique_ptr<ShardedRenderer> make_sharded_renderer(const ShardFlags& f, const Scene& scene,
                                                       const std::string& backend, Precision precision, int threads) {
    if (f.shards <= 1) return nullptr;
    const std::vector<int> devices = shard_devices(f, backend);
    if (backend != "cuda" && f.composite == "device")
        throw Error("--composite device: backend '" + backend + "' has no device memory; use host or auto");
    auto make = [&](int shard) {
        return make_renderer(backend, precision, threads, devices[static_cast<std::size_t>(shard) % devices.size()]);
    };
    std::unique_ptr<ShardedRenderer> sharded;
    try {
        sharded = std::make_unique<ShardedRenderer>(scene, f.shards, make, threads);
    } catch (const Error& e) {
        throw Error("--shards " + std::to_string(f.shards) + ": " + e.what());
    }
    sharded->set_concurrent(backend == "cuda" && devices.size() > 1);
    if (backend == "cuda" && f.composite != "host")
        sharded->set_compositor(make_partial_compositor(backend, devices[0]));
    return sharded;
}

std::string describe_sharding(const ShardFlags& f, const ShardedRenderer& sharded, const std::string& backend) {
    std::string text = sharded.name();
    if (backend == "cuda") {
        const std::vector<int> devices = shard_devices(f, backend);
        text += (devices.size() == 1 ? " on device " : " on devices ") + join(devices);
    }
    text += sharded.compositor_device() >= 0 ? ", composited on device " + std::to_string(sharded.compositor_device())
                                             : ", composited on the host";
    return text;
}

}  // namespace catgs::cli
