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

/// The axes a .spz file's data is in. The format has no field for it: Niantic's library writes
/// RUB (x right, y up, z back: its documented convention), splat-transform 3.7.0 writes the
/// PLY's RDF values unconverted (`from: UNSPECIFIED`) and reads them back the same way.
enum class SpzAxes {
    rdf,  ///< as splat-transform writes: no conversion
    rub,  ///< as Niantic's spz library writes: y and z flip to reach catgs' RDF
};

struct LoadOptions {
    /// Records with non-finite values or a zero-norm quaternion are an error by default;
    /// with this set they are dropped and counted in LoadReport::dropped_invalid.
    bool drop_invalid = false;
    /// Move the origin to the centre of the bounds, or of the bulk where stray Gaussians set the
    /// bounds (scene_origin, see Scene). Tests that need the naive absolute-float layout turn
    /// it off.
    bool recentre = true;
    /// load_scene only: reorder the Gaussians along a Morton curve and cut them into spatial
    /// chunks (partition_into_chunks), for chunk-level culling. The single-format readers
    /// keep the file's order.
    bool chunks = true;
    /// A file that declares more records than this is refused before anything is allocated
    /// for it. The default leaves only the bound the file size sets; fuzz targets and
    /// memory-capped callers lower it.
    std::uint64_t max_records = std::numeric_limits<std::uint64_t>::max();
    /// A file whose declared records would take more than this many bytes of Scene
    /// (scene_bytes_per_gaussian at the file's SH degree, what Scene::bytes() of the result
    /// counts) is refused before anything is allocated for it. Memory-capped callers set it
    /// rather than deriving max_records from one degree's cost. Loading itself briefly needs
    /// 24 bytes more per record (the double positions, until the origin is known).
    std::uint64_t max_scene_bytes = std::numeric_limits<std::uint64_t>::max();
    /// The directory that the files a scene names beside itself (an unbundled SOG's textures
    /// next to its meta.json) must lie in once links are followed; such a file outside it is
    /// refused, naming it. The server sets its --scene-root, so that a link in the root cannot
    /// reach files it would refuse to open as scenes. Empty: not checked.
    std::string scene_root;
    /// read_spz: the axes of the file's data (see SpzAxes).
    SpzAxes spz_axes = SpzAxes::rdf;
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

/// Niantic .spz, versions 2 and 3 (one gzip stream: a 16-byte header, then every Gaussian's
/// position, then every alpha, colour, scale, rotation and SH block). Positions are 24-bit
/// fixed point, scales log(s) = byte / 16 - 10, alpha linear byte / 255, colour f_dc =
/// (byte / 255 - 0.5) / 0.15, rotations (x, y, z) bytes with w >= 0 derived (v2) or the
/// smallest three in 10 bits (v3), SH coefficients (byte - 128) / 128 with the channel the
/// fastest axis. The header's SH degree (0..3) is the scene's. options.spz_axes says whether
/// to convert from RUB. The decompressed size is checked against the header's count before
/// anything is inflated past it, so a gzip bomb costs no more than the count it declares.
Scene read_spz(const std::string& path, const LoadOptions& options = {}, LoadReport* report = nullptr);

/// SuperSplat's compressed PLY (.compressed.ply): binary little-endian PLY with an element
/// `chunk` of per-256-Gaussian float bounds (min/max x, y, z, scale_x..z and optionally r, g,
/// b), an element `vertex` of uint32 packed_position (11/10/11 bits), packed_rotation (2-bit
/// largest-component index and three 10-bit components), packed_scale (11/10/11, log) and
/// packed_color (RGBA 8 bits), and an optional element `sh` of uint8 f_rest_* (9, 24 or 45:
/// SH degree 1..3). Stored in the PLY's RDF axes.
Scene read_compressed_ply(const std::string& path, const LoadOptions& options = {}, LoadReport* report = nullptr);

/// PlayCanvas SOG, meta.json version 2 (splat-transform's): a .sog zip of WebP textures and
/// meta.json, or an unbundled meta.json whose textures are plain file names beside it.
/// Positions are 16-bit steps of sign(v) ln(|v| + 1) between means.mins and maxs, scales and
/// f_dc index 256-entry codebooks, opacity is linear byte / 255, quaternions the smallest
/// three plus a largest-component tag, SH (shN.bands 1..3, the scene's degree) a palette of
/// codebook-indexed centroids picked by a 16-bit label. Stored in the PLY's RDF axes. Every
/// zip entry and texture is checked against what meta.json's count needs before it is
/// inflated or decoded; version 1 (no 'version' key) is refused.
Scene read_sog(const std::string& path, const LoadOptions& options = {}, LoadReport* report = nullptr);

/// glTF 2.0 binary (.glb) with KHR_gaussian_splatting primitives (as splat-transform 3.7.0
/// writes): POSITION, KHR_gaussian_splatting:ROTATION (x, y, z, w), :SCALE (linear), :OPACITY
/// (linear) and :SH_DEGREE_l_COEF_c (f_dc and f_rest, VEC3 per coefficient; the highest
/// complete degree is the scene's), float or normalised integer accessors. glTF's axes are
/// LUF (+x left, +y up, +z forward); they are turned 180 degrees about z into the PLY's RDF,
/// rotating positions, quaternions and SH coefficients. Every primitive with the extension is
/// read; node transforms and buffers in other files are refused.
Scene read_glb(const std::string& path, const LoadOptions& options = {}, LoadReport* report = nullptr);

/// Binary little-endian graphdeco PLY. x, y, z (world coordinates: origin + position,
/// formed in double), scale_* (log) and opacity (logit, clamped to +-40) are written as
/// double, so that reading the file back gives bit-identical activated floats; every other
/// property is float. Exact for positions when the scene's origin is the centre of its
/// bounds (as after loading with recentre, unless stray Gaussians moved it to the bulk's:
/// scene_origin) or zero.
void write_ply(const Scene& scene, const std::string& path);

/// Opens a scene from a path (the format recognised by content, .splat by extension: see
/// scene_format.hpp) or a generator spec
/// "builtin:city?gaussians=N&seed=S" (see builtin_city.hpp), partitioned into spatial chunks
/// unless options.chunks is off (Gaussian order then changes; see partition_into_chunks).
Scene load_scene(const std::string& spec, const LoadOptions& options = {}, LoadReport* report = nullptr);

}  // namespace catgs
