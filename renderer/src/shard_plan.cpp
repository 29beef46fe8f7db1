#include "catgs/shard_plan.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <utility>

#include "catgs/error.hpp"

namespace catgs {
namespace {

constexpr double kInfinity = std::numeric_limits<double>::infinity();

// Planes a node evaluates per axis at most: each costs two binary searches, and 2^16 gaps of a
// node's balanced window find the fewest straddlers to within a few of the best gap's count
// even at 10^8 Gaussians, in well under a second per node.
constexpr std::size_t kMaxCandidates = std::size_t{1} << 16;

/// A candidate plane and what it does to the node.
struct Cut {
    int axis = -1;
    double plane = -kInfinity;  // no candidate: everything goes above
    std::uint64_t straddling = 0;
    double imbalance = kInfinity;  // |below - the below side's share|, in Gaussians
    bool balanced = false;         // imbalance within the tolerance

    // Balanced cuts first, then the fewest straddlers; among unbalanced ones the most balanced.
    bool better_than(const Cut& other) const {
        if (balanced != other.balanced) return balanced;
        if (balanced)
            return straddling != other.straddling ? straddling < other.straddling : imbalance < other.imbalance;
        return imbalance != other.imbalance ? imbalance < other.imbalance : straddling < other.straddling;
    }
};

/// The node's members' coordinates along one axis, sorted: means, and the two ends of their
/// extents (finite ones; `unbounded` counts the finite means of infinite extent, which straddle
/// every plane).
struct AxisSpans {
    std::vector<float> means;
    std::vector<double> lo, hi;
    std::uint64_t unbounded = 0;
};

AxisSpans axis_spans(const Scene& scene, const std::vector<std::uint32_t>& members, const std::vector<double>& extents,
                     int axis) {
    AxisSpans s;
    s.means.reserve(members.size());
    s.lo.reserve(members.size());
    s.hi.reserve(members.size());
    for (std::size_t j = 0; j < members.size(); ++j) {
        const float p = scene.positions[3 * static_cast<std::size_t>(members[j]) + static_cast<std::size_t>(axis)];
        if (!std::isfinite(p)) continue;  // never drawn; goes above, outside every count
        s.means.push_back(p);
        if (std::isfinite(extents[j])) {
            s.lo.push_back(static_cast<double>(p) - extents[j]);
            s.hi.push_back(static_cast<double>(p) + extents[j]);
        } else {
            ++s.unbounded;
        }
    }
    std::sort(s.means.begin(), s.means.end());
    std::sort(s.lo.begin(), s.lo.end());
    std::sort(s.hi.begin(), s.hi.end());
    return s;
}

/// The best plane of a node whose below side should hold `share` of its members (non-finite
/// means, never drawn, go above). Candidates:
/// the gaps between consecutive means along each axis (the plane halfway across), of those that
/// balance the node, at most kMaxCandidates per axis evenly spread. A chunk face moved into the
/// gap beyond it is one of them, so a plane follows the chunks wherever that balances the node
/// and costs no more straddlers.
Cut choose_cut(const Scene& scene, const std::vector<std::uint32_t>& all_members, double share,
               std::size_t max_samples) {
    // A node larger than max_samples chooses on every stride-th member.
    std::vector<std::uint32_t> sampled;
    const std::size_t stride = (all_members.size() + max_samples - 1) / std::max<std::size_t>(max_samples, 1);
    if (stride > 1)
        for (std::size_t j = 0; j < all_members.size(); j += stride) sampled.push_back(all_members[j]);
    const std::vector<std::uint32_t>& members = stride > 1 ? sampled : all_members;
    std::vector<double> extents(members.size());
    for (std::size_t j = 0; j < members.size(); ++j) extents[j] = gaussian_shard_extent(scene, members[j]);
    const double node = static_cast<double>(members.size());
    const double target = share * node;
    const double tolerance = kShardBalanceTolerance * std::min(target, node - target);
    Cut best;
    for (int axis = 0; axis < 3; ++axis) {
        const AxisSpans s = axis_spans(scene, members, extents, axis);
        const std::size_t n = s.means.size();
        if (n < 2) continue;
        auto consider = [&](std::size_t below) {  // the plane between means below - 1 and below
            if (!(s.means[below - 1] < s.means[below])) return;
            Cut c;
            c.axis = axis;
            c.plane = 0.5 * (static_cast<double>(s.means[below - 1]) + static_cast<double>(s.means[below]));
            // Extents with lo < plane <= hi cross it; hi < plane implies lo < plane.
            const auto lo_below = std::lower_bound(s.lo.begin(), s.lo.end(), c.plane) - s.lo.begin();
            const auto hi_below = std::lower_bound(s.hi.begin(), s.hi.end(), c.plane) - s.hi.begin();
            c.straddling = static_cast<std::uint64_t>(lo_below - hi_below) + s.unbounded;
            c.imbalance = std::fabs(static_cast<double>(below) - target);
            c.balanced = c.imbalance <= tolerance;
            if (c.better_than(best)) best = c;
        };
        const auto clamp = [&](double v) {
            return static_cast<std::size_t>(std::clamp(v, 1.0, static_cast<double>(n - 1)));
        };
        const std::size_t first = clamp(std::ceil(target - tolerance)), last = clamp(std::floor(target + tolerance));
        if (first <= last) {
            const std::size_t step = std::max<std::size_t>(1, (last - first) / kMaxCandidates);
            for (std::size_t below = first; below <= last; below += step) consider(below);
        }
        // The most balanced gaps, should no balanced one be distinct (many equal means).
        for (std::size_t below = clamp(std::round(target)); below < n; ++below)
            if (s.means[below - 1] < s.means[below]) {
                consider(below);
                break;
            }
        for (std::size_t below = clamp(std::round(target)); below >= 1; --below)
            if (s.means[below - 1] < s.means[below]) {
                consider(below);
                break;
            }
    }
    return best;
}

/// The node's Gaussians whose extent crosses the plane (as choose_cut counts them).
std::uint64_t count_straddling(const Scene& scene, const std::vector<std::uint32_t>& members, int axis, double plane) {
    std::uint64_t count = 0;
    for (std::uint32_t i : members) count += straddles_plane(scene, i, axis, plane);
    return count;
}

int build_node(ShardPlan& plan, const Scene& scene, std::vector<std::uint32_t> members, int shards, int first_shard,
               std::size_t max_samples) {
    const int index = static_cast<int>(plan.nodes.size());
    plan.nodes.emplace_back();
    if (shards == 1) {
        plan.nodes[static_cast<std::size_t>(index)].shard = first_shard;
        plan.members[static_cast<std::size_t>(first_shard)] = std::move(members);
        return index;
    }
    // Uneven k splits unevenly: 3 shards are 1 below and 2 above.
    const int below_shards = shards / 2;
    Cut cut = choose_cut(scene, members, static_cast<double>(below_shards) / shards, max_samples);
    if (cut.axis >= 0) cut.straddling = count_straddling(scene, members, cut.axis, cut.plane);
    std::vector<std::uint32_t> below, above;
    for (std::uint32_t i : members) {
        const bool is_below =
            cut.axis >= 0 &&
            static_cast<double>(scene.positions[3 * static_cast<std::size_t>(i) + static_cast<std::size_t>(cut.axis)]) <
                cut.plane;
        (is_below ? below : above).push_back(i);
    }
    members.clear();
    members.shrink_to_fit();
    plan.straddling += cut.straddling;
    const int below_node = build_node(plan, scene, std::move(below), below_shards, first_shard, max_samples);
    const int above_node =
        build_node(plan, scene, std::move(above), shards - below_shards, first_shard + below_shards, max_samples);
    ShardNode& n = plan.nodes[static_cast<std::size_t>(index)];
    n.axis = std::max(cut.axis, 0);
    n.plane = cut.plane;
    n.below = below_node;
    n.above = above_node;
    n.straddling = cut.straddling;
    return index;
}

void visit(const ShardPlan& plan, int node, const std::array<double, 3>& eye, std::vector<int>& order) {
    const ShardNode& n = plan.nodes[static_cast<std::size_t>(node)];
    if (n.shard >= 0) {
        order.push_back(n.shard);
        return;
    }
    const bool below_first = !(eye[static_cast<std::size_t>(n.axis)] > n.plane);
    visit(plan, below_first ? n.below : n.above, eye, order);
    visit(plan, below_first ? n.above : n.below, eye, order);
}

}  // namespace

bool straddles_plane(const Scene& scene, std::size_t i, int axis, double plane) {
    const double p = scene.positions[3 * i + static_cast<std::size_t>(axis)];
    const double e = gaussian_shard_extent(scene, i);
    return p - e < plane && p + e >= plane;  // false for a non-finite mean
}

double gaussian_shard_extent(const Scene& scene, std::size_t i) {
    const double opacity = scene.opacities[i];
    const float* s = &scene.scales[3 * i];
    const double largest = std::max({std::fabs(s[0]), std::fabs(s[1]), std::fabs(s[2])});
    if (!std::isfinite(opacity) || !std::isfinite(largest)) return kInfinity;
    if (!(opacity > kMinAlpha)) return 0;
    const double sigmas = std::min(kChunkSigmas, std::sqrt(2.0 * std::log(opacity / kMinAlpha)));
    return sigmas * largest;
}

ShardPlan plan_shards(const Scene& scene, int shards, std::size_t max_samples) {
    if (shards < 1 || shards > kMaxShards)
        throw Error("shard plan: " + std::to_string(shards) + " shards: expected 1.." + std::to_string(kMaxShards));
    scene.check_consistent("shard plan: scene");
    const std::size_t chunks = std::max<std::size_t>(scene.chunks.size(), 1);
    if (static_cast<std::size_t>(shards) > chunks)
        throw Error("shard plan: " + std::to_string(shards) + " shards but the scene has " + std::to_string(chunks) +
                    " chunk" + (chunks == 1 ? "" : "s") + " (" + std::to_string(scene.count()) +
                    " Gaussians): a shard is cut along chunks, at most one shard per chunk "
                    "(partition_into_chunks makes one per " +
                    std::to_string(kChunkGaussians) + " Gaussians)");
    ShardPlan plan;
    plan.origin = scene.origin;
    plan.members.resize(static_cast<std::size_t>(shards));
    std::vector<std::uint32_t> all(scene.count());
    for (std::size_t i = 0; i < all.size(); ++i) all[i] = static_cast<std::uint32_t>(i);
    // Fewer than 2 samples cannot place a plane between means.
    build_node(plan, scene, std::move(all), shards, 0, std::max<std::size_t>(max_samples, 2));
    return plan;
}

std::vector<int> shard_visibility_order(const ShardPlan& plan, const std::array<double, 3>& eye) {
    std::vector<int> order;
    if (plan.nodes.empty()) return order;
    const std::array<double, 3> relative{eye[0] - plan.origin[0], eye[1] - plan.origin[1], eye[2] - plan.origin[2]};
    visit(plan, 0, relative, order);
    return order;
}

std::vector<int> shard_visibility_order(const ShardPlan& plan, const Camera& camera) {
    return shard_visibility_order(plan, camera_centre(camera.pose));
}

Scene extract_shard(const Scene& scene, const std::vector<std::uint32_t>& members) {
    const std::size_t n = scene.count();
    for (std::size_t j = 0; j < members.size(); ++j)
        if (members[j] >= n || (j > 0 && members[j] <= members[j - 1]))
            throw Error("extract_shard: member " + std::to_string(j) + " is Gaussian " + std::to_string(members[j]) +
                        ": members must be ascending and below the scene's " + std::to_string(n) + " Gaussians");
    Scene out;
    out.origin = scene.origin;
    out.sh_degree = scene.sh_degree;
    out.resize(members.size());
    const std::size_t stride = scene.sh_floats_per_gaussian();
    for (std::size_t j = 0; j < members.size(); ++j) {
        const std::size_t i = members[j];
        std::copy_n(&scene.positions[3 * i], 3, &out.positions[3 * j]);
        std::copy_n(&scene.scales[3 * i], 3, &out.scales[3 * j]);
        std::copy_n(&scene.rotations[4 * i], 4, &out.rotations[4 * j]);
        out.opacities[j] = scene.opacities[i];
        std::copy_n(&scene.sh[stride * i], stride, &out.sh[stride * j]);
    }
    std::size_t j = 0;
    for (const Chunk& c : scene.chunks) {
        const std::size_t begin = j;
        while (j < members.size() && members[j] < c.end) ++j;
        if (j == begin) continue;
        Chunk part;
        part.begin = static_cast<std::uint32_t>(begin);
        part.end = static_cast<std::uint32_t>(j);
        out.chunks.push_back(part);
    }
    out.update_chunk_bounds();
    out.update_bounds();
    return out;
}

}  // namespace catgs
