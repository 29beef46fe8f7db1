// The shard plan of a sharded frame (sharded_renderer.hpp): a scene cut into k spatial shards
// by axis-aligned planes arranged as a k-d tree (a BSP of planes), so that any two shards'
// cells lie on either side of one plane and a camera orders them front to back by its side
// of that plane.
//
// Each node picks, among the planes halfway across the gaps between consecutive means that
// give its two sides their share of Gaussians (within kShardBalanceTolerance), the one that the
// fewest Gaussians straddle: those whose extent (gaussian_shard_extent) crosses the plane, the
// only ones whose blend order a shard can get wrong. The faces of the scene's chunks (Scene::
// chunks, partition_into_chunks) moved into the gap beyond them are among these planes, so a
// plane follows the chunks where that balances the node and costs no more straddlers; a chunk
// that a plane cuts is split, and each shard's scene keeps the pieces as its chunks. Gaussians
// go to the side of their mean, and keep their scene order within a shard, so that equal
// depths still blend in Gaussian-index order.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "catgs/camera.hpp"
#include "catgs/scene.hpp"

namespace catgs {

/// Each side of a node may hold its share of the node's Gaussians give or take this fraction
/// of the smaller side's share: a GPU's frame time follows its Gaussians and the slowest shard
/// sets the frame's, so the margin is small (over the 3 levels of 8 shards a shard holds 0.73
/// to 1.33 of an even share), yet it lets a plane move to a street between blocks instead of
/// cutting through a wall.
inline constexpr double kShardBalanceTolerance = 0.1;

/// A node with more Gaussians than this chooses its plane on every stride-th of them: a node's
/// choice sorts its Gaussians along each axis, which at 10^8 would take minutes per level,
/// while the balance of 2^20 samples is the node's to within 0.1%. The straddlers of the plane
/// chosen are then counted over the whole node.
inline constexpr std::size_t kShardPlanSamples = std::size_t{1} << 20;

/// The most shards a plan cuts: a GPU each, and more GPUs than this share no host.
inline constexpr int kMaxShards = 64;

struct ShardNode {
    int axis = -1;                 ///< 0..2, or -1 for a leaf
    double plane = 0;              ///< relative to the scene origin: means below it go to `below`
    int below = -1;                ///< child node of the means < plane
    int above = -1;                ///< child node of the others (and of non-finite means)
    int shard = -1;                ///< a leaf's shard
    std::uint64_t straddling = 0;  ///< the node's Gaussians whose extent crosses the plane
};

struct ShardPlan {
    std::array<double, 3> origin{0, 0, 0};            ///< the scene's: planes are relative to it
    std::vector<ShardNode> nodes;                     ///< nodes[0] is the root
    std::vector<std::vector<std::uint32_t>> members;  ///< each shard's Gaussians, in scene order
    std::uint64_t straddling = 0;                     ///< the sum over the planes

    int shards() const { return static_cast<int>(members.size()); }
};

/// How far a Gaussian reaches from its mean for the straddling test, in metres: the
/// opacity-aware extent (alpha reaches 1/255 at sqrt(2 ln(255 opacity)) sigma of the largest
/// scale), at most kChunkSigmas sigma as chunk culling counts; 0 for one too faint to draw.
/// +inf when a scale or the opacity is not finite.
double gaussian_shard_extent(const Scene& scene, std::size_t i);

/// Whether Gaussian i's extent (gaussian_shard_extent) crosses the plane at `plane` on `axis`
/// (relative to the scene origin): the straddlers a plan counts. False for a non-finite mean.
bool straddles_plane(const Scene& scene, std::size_t i, int axis, double plane);

/// Cuts `scene` into `shards` shards, each node choosing on at most `max_samples` of its
/// Gaussians. Throws catgs::Error naming the problem when shards < 1, shards > kMaxShards, or
/// shards is more than the scene's chunks (a scene without chunks counts as one).
ShardPlan plan_shards(const Scene& scene, int shards, std::size_t max_samples = kShardPlanSamples);

/// The shards front to back for a camera at `eye` (world coordinates): at each node the
/// camera's side of the plane first (the below side when the eye is on the plane). Exact for
/// the Gaussians that straddle no plane and whose blend order follows their side of it.
std::vector<int> shard_visibility_order(const ShardPlan& plan, const std::array<double, 3>& eye);
std::vector<int> shard_visibility_order(const ShardPlan& plan, const Camera& camera);

/// The scene of one shard: its members in scene order, the same origin (so that every frame
/// computes what the unsharded scene computes for them), each chunk of the scene restricted to
/// the members it holds.
Scene extract_shard(const Scene& scene, const std::vector<std::uint32_t>& members);

}  // namespace catgs
