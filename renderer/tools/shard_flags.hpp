// --shards, --shard-devices and --composite, as catgs-render and catgs-bench take them: one
// frame of the scene cut into spatial shards, one renderer each, spread over the GPUs and
// composited front to back (docs/sharding.md).
#pragma once

#include <CLI/CLI.hpp>

#include <memory>
#include <string>

#include "catgs/renderer.hpp"
#include "catgs/scene.hpp"
#include "catgs/sharded_renderer.hpp"

namespace catgs::cli {

struct ShardFlags {
    int shards = 1;
    std::string devices = "all";
    std::string composite = "auto";
};

void add_shard_flags(CLI::App& app, ShardFlags& f);

/// The sharded renderer the flags ask for; null when they ask for one shard. The CPU backend:
/// K CPU renderers in turn, composited on the host. CUDA: shard i on the (i mod n)-th of the n
/// devices --shard-devices names, rendering at once when n > 1, and composited on the first of
/// them (auto, device) or on the host (host). Throws catgs::Error naming the flag at fault.
std::unique_ptr<ShardedRenderer> make_sharded_renderer(const ShardFlags& f, const Scene& scene,
                                                       const std::string& backend, Precision precision, int threads);

/// "2 shards of cuda/float on devices 0, 1, composited on device 0", for the tools' headers.
std::string describe_sharding(const ShardFlags& f, const ShardedRenderer& sharded, const std::string& backend);

}  // namespace catgs::cli
