// Scene readers and writers: graphdeco 3DGS PLY (binary little/big endian and ASCII) and
// the 32-byte .splat format, plus `load_scene`, which also accepts builtin: generators.
//
// Every reader validates as it goes. Bad input never crashes, hangs or allocates more than
// the file could hold; it raises catgs::Error with one line that names the file, the problem
// and where it was found (property, record index or byte offset).
#pragma once

#include <cstddef>
#include <cstdint>
#include <limits>
#include <string>

#include "catgs/progress.hpp"
#include "catgs/scene.hpp"

namespace catgs {

struct LoadOptions {
    /// Records with non-finite values or a zero-norm quaternion are an error by default;
    /// with this set they are dropped and counted in LoadReport::dropped_invalid.
    bool drop_invalid = false;
    /// Move the origin to the centre of the bounds (see Scene). Tests that need the naive
    /// absolute-float layout turn it off.
    bool recentre = true;
    /// load_scene only: reorder the Gaussians along a Morton curve and cut them into spatial
    /// chunks (partition_into_chunks), for chunk-level culling. The single-format readers
    /// keep the file's order.
    bool chunks = true;
    /// A file that declares more records than this is refused before anything is allocated
    /// for it. The default leaves only the bound the file size sets; fuzz targets and
    /// memory-capped callers lower it.
    std::uint64_t max_records = std::numeric_limits<std::uint64_t>::max();
    Progress progress;
};

struct LoadReport {
    std::size_t records = 0;              ///< records in the file
    std::size_t dropped_invalid = 0;      ///< non-finite or zero-norm quaternion (drop_invalid)
    std::size_t dropped_transparent = 0;  ///< opacity < 1/255: can never contribute
};

/// graphdeco 3DGS PLY. Properties are located by name in any order, float or double; extra
/// properties are ignored; SH degree follows from the number of f_rest_* (0, 9, 24 or 45),
/// which are stored channel-major (all R coefficients, then G, then B).
/// Activations are applied: exp to scale_*, sigmoid to opacity, quaternions normalised
/// (a quaternion already unit to |norm^2 - 1| <= 2^-22 is kept as it is: normalising a
/// float unit quaternion again moves ~1% of them by an ulp and would break the exact
/// write/read round trip).
Scene read_ply(const std::string& path, const LoadOptions& options = {}, LoadReport* report = nullptr);

/// The 32-byte .splat format: 3 float32 position, 3 float32 linear scale, RGBA uint8
/// (colour = 0.5 + 0.2820948 * f_dc, A = 255 * opacity), quaternion uint8 (q * 128 + 128)
/// in (w, x, y, z) order. SH degree 0.
Scene read_splat(const std::string& path, const LoadOptions& options = {}, LoadReport* report = nullptr);

/// Binary little-endian graphdeco PLY. x, y, z (world coordinates: origin + position,
/// formed in double), scale_* (log) and opacity (logit, clamped to +-40) are written as
/// double, so that reading the file back gives bit-identical activated floats; every other
/// property is float. Exact for positions when the scene's origin is the centre of its
/// bounds (as after loading with recentre) or zero.
void write_ply(const Scene& scene, const std::string& path);

/// Opens a scene from a path (.ply or .splat, chosen by extension) or a generator spec
/// "builtin:city?gaussians=N&seed=S" (see builtin_city.hpp), partitioned into spatial chunks
/// unless options.chunks is off (Gaussian order then changes; see partition_into_chunks).
Scene load_scene(const std::string& spec, const LoadOptions& options = {}, LoadReport* report = nullptr);

}  // namespace catgs
