// The Gaussian scene, held as structure-of-arrays so that every stage streams only the
// fields it needs, and so that the arrays copy to the GPU as they are.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "catgs/constants.hpp"

namespace catgs {

struct Bounds {
    std::array<double, 3> min{0, 0, 0};
    std::array<double, 3> max{0, 0, 0};
};

/// A spatial chunk of the scene (chunk-level culling, stages/chunks.hpp): Gaussians
/// [begin, end) of the scene order, the box of their means (relative to the origin; +-inf when
/// a member is not finite, so the chunk is never culled) and its largest footprint radius,
/// kChunkSigmas times the largest scale of any member, in metres.
struct Chunk {
    float lo[3] = {0, 0, 0};
    float hi[3] = {0, 0, 0};
    float radius = 0;
    std::uint32_t begin = 0, end = 0;
};

/// Host bytes one Gaussian takes in a Scene of this SH degree, as Scene::bytes() counts them:
/// 11 floats of position, scale, rotation and opacity, and 3 per SH coefficient (56, 92, 152
/// and 236 bytes at degrees 0 to 3). A memory limit must use the file's degree: the least,
/// degree 0's, lets a degree-3 file allocate 4.2 times the limit before it is measured.
constexpr std::size_t scene_bytes_per_gaussian(int sh_degree) {
    return sizeof(float) * (11 + 3 * static_cast<std::size_t>(sh_coefficient_count(sh_degree)));
}

/// Positions are float offsets from a double-precision origin chosen at load (scene_origin:
/// the centre of the bounds, or of the bulk where a few stray Gaussians set the bounds): a UAV
/// capture in UTM coordinates sits 10^6..10^7 m from the world origin, where a float has a
/// resolution of 0.06..1 m. Every per-frame computation is relative to this origin (see
/// camera.hpp, make_view).
struct Scene {
    std::array<double, 3> origin{0, 0, 0};
    std::vector<float> positions;  ///< 3 per Gaussian, world minus origin
    std::vector<float> scales;     ///< 3 per Gaussian, activated (exp of the stored log)
    std::vector<float> rotations;  ///< 4 per Gaussian, unit quaternion (w, x, y, z)
    std::vector<float> opacities;  ///< 1 per Gaussian, activated (sigmoid of the logit)
    /// sh_coefficient_count(sh_degree) * 3 per Gaussian, laid out [gaussian][coefficient][rgb].
    /// Coefficient 0 is the DC term f_dc.
    std::vector<float> sh;
    int sh_degree = 0;
    Bounds bounds;  ///< world coordinates (origin included)
    /// Contiguous chunks in scene order covering every Gaussian (partition_into_chunks), or
    /// empty: renderers then treat the scene as one unculled run. They describe positions and
    /// scales, so code that edits those must partition again (or clear them).
    std::vector<Chunk> chunks;

    std::size_t count() const { return opacities.size(); }
    int sh_coefficients() const { return sh_coefficient_count(sh_degree); }
    std::size_t sh_floats_per_gaussian() const { return 3u * static_cast<std::size_t>(sh_coefficients()); }
    std::size_t bytes() const;

    /// Resizes every array for n Gaussians at the current SH degree.
    void resize(std::size_t n);
    /// Recomputes bounds from the positions (world = origin + position).
    void update_bounds();
    /// Recomputes every chunk's box and radius from the positions and scales.
    void update_chunk_bounds();
    /// Moves the origin to scene_origin's choice, re-expressing positions relative to it.
    /// Positions are rebased in double so nothing is lost beyond the final float rounding.
    void recentre();
    /// Throws catgs::Error naming `what` if array sizes disagree with count() or the degree,
    /// or if the chunks do not cover the Gaussians in order with at most kChunkGaussians each.
    void check_consistent(const std::string& what) const;
};

/// Of a scene's Gaussians, the share at each end of an axis that scene_origin counts as
/// strays: a capture's floaters and far-away sky points are a small fraction of it.
inline constexpr double kOriginStrayShare = 0.01;
/// How far (in half-extents of the bulk) the centre of the bounds may lie from the bulk's before
/// scene_origin takes the bulk's: there the bulk's positions keep all but 6 bits of the float
/// resolution they have around their own centre, and a normal scene keeps the centre of its
/// bounds (write_ply's exact round trip).
inline constexpr double kOriginStrayFactor = 64.0;
/// At most this many Gaussians, evenly strided, are sampled for the bulk's percentiles.
inline constexpr std::size_t kOriginSample = std::size_t{1} << 20;

/// The origin for positions of world coordinates `world(i, axis)` (i < n) within `bounds`, per
/// axis: the centre of the bounds, unless it lies more than kOriginStrayFactor half-extents
/// of the bulk (the kOriginStrayShare .. 1 - kOriginStrayShare percentiles) from the bulk's
/// centre; then the bulk's centre. One Gaussian 10^7 m out would otherwise put the origin
/// 5 * 10^6 m from all the others and round their positions to 0.5 m (a float's grain there),
/// in every precision.
std::array<double, 3> scene_origin(const Bounds& bounds, std::size_t n,
                                   const std::function<double(std::size_t, int)>& world);

/// A one-line description: count, SH degree, bounds, origin and memory.
std::string describe(const Scene& scene);
/// The same, as a JSON object.
std::string describe_json(const Scene& scene);

}  // namespace catgs
