// Named constants of the rendering semantics, each with the reason it has its value.
// Both backends read these; changing one changes the reference and the GPU alike.
#pragma once

#include <cstdint>

#include "catgs/hd.hpp"

namespace catgs {

inline constexpr double kPi = 3.14159265358979323846;

/// Tiles are 16x16 pixels: one CUDA block rasterizes one tile (256 threads of one pixel, the
/// layout of graphdeco 3DGS and gsplat, or 128 of two); the sort key stores tile ids, so it
/// also sets key bits.
inline constexpr int kTileSize = 16;

/// Default near plane (view-space z). Gaussians at z <= near are culled; 0.2 is graphdeco's
/// value, and it keeps 1/z of the projection Jacobian bounded.
inline constexpr double kDefaultNearPlane = 0.2;

/// The Jacobian of the perspective projection is evaluated at x/z, y/z clamped to 1.3x the
/// half field of view (principal-point aware, as gsplat): Gaussians far outside the image
/// would otherwise get huge, numerically useless 2D covariances.
inline constexpr double kJacobianClampFactor = 1.3;

/// Added to the diagonal of every 2D covariance (in pixels^2): a low-pass filter so that a
/// Gaussian never becomes thinner than about one pixel (graphdeco's 0.3, gsplat's eps2d).
inline constexpr double kCovarianceBlur = 0.3;

/// Per-Gaussian alpha is capped at 0.99 so that one Gaussian never makes a pixel fully
/// opaque on its own (graphdeco, gsplat MAX_ALPHA). It is float's 0.99 (0.99000001) in every
/// precision, as graphdeco's float kernel has it: with the exact 0.99, two layers at the cap
/// leave T = (1 - 0.99)^2 = 1e-4 exactly, a tie with kMinTransmittance that float (which
/// stops: 0.99f > 0.99) and double (which draws the second layer: 1 - 0.99 > 0.01 there)
/// break opposite ways, 2.5 levels apart at such a pixel. With float's value every precision
/// gets T = 9.99998e-5 and stops. (CATGS_TEST_SEED=1859812409409949438, opacities family.)
inline constexpr double kMaxAlpha = static_cast<double>(0.99f);

/// A Gaussian whose alpha at a pixel is below 1/255 is skipped: it cannot change an 8-bit
/// value. The same bound defines opacity-aware culling and the load-time opacity filter.
inline constexpr double kMinAlpha = 1.0 / 255.0;

/// A pixel stops blending before the Gaussian that would bring its transmittance below 1e-4
/// (graphdeco's exclusive stop; (1 - 0.99)^2 in gsplat's words): what lies behind can add at
/// most 1e-4 of light, far under half an 8-bit level.
inline constexpr double kMinTransmittance = 1e-4;

/// Spherical-harmonics colour is offset by 0.5 (the DC term of a trained scene is centred
/// on grey) and clamped at zero, as graphdeco does; the upper clamp happens on output.
inline constexpr double kShColourOffset = 0.5;

/// SH colours are clamped at this value: far above anything displayable (outputs clamp to 1),
/// yet small enough that C + T * background stays finite in float for any coefficients.
inline constexpr double kMaxShColour = 1e4;

/// The highest SH degree a scene may carry (16 coefficients per channel).
inline constexpr int kMaxShDegree = 3;

/// Number of SH coefficients per colour channel for a degree.
CATGS_HD constexpr int sh_coefficient_count(int degree) {
    return (degree + 1) * (degree + 1);
}

/// Graphdeco's 3-sigma radius uses max(0.1, mid^2 - det) under the square root so that a
/// circular 2D Gaussian still gets a well-defined eigenvalue spread.
inline constexpr double kBBoxEigenFloor = 0.1;

/// The 3-sigma extent of the graphdeco baseline (`bbox3sigma`).
inline constexpr double kBBoxSigmas = 3.0;

/// The largest image side any renderer accepts (and the protocol's, request_validation.hpp): a
/// 16384x16384 frame already holds 3.2 GB of float colour on the CPU; a larger request, say a
/// trajectory line's 100000x100000, is refused by name instead of allocating without bound.
inline constexpr int kMaxImageSide = 16384;

/// Fields of view (degrees) that the tools' --fov and the protocol's focal lengths and
/// horizontal_fov_degrees may give: a focal length that a float cannot hold renders a blank
/// frame, and this range keeps it within about 4e-4..1e9 pixels for every image size up to
/// kMaxImageSide.
inline constexpr double kMinFieldOfViewDegrees = 1e-3;
inline constexpr double kMaxFieldOfViewDegrees = 179.9;

/// Most poses a speculative window may hold (CaT-GS: W in 1..16); a window's validity mask
/// is a 32-bit word.
inline constexpr int kMaxWindow = 16;

/// Chunk-level culling (stages/chunks.hpp). Gaussians per chunk: ~6000 chunks for a 6M scene
/// (a few microseconds to test on the GPU) and a multiple of the 256-thread block, so that
/// the blocks of the compacted index space map onto whole chunks.
inline constexpr std::uint32_t kChunkGaussians = 1024;

/// A chunk's radius counts this many standard deviations of its largest scale: no culling
/// mode draws farther (opacity-aware stops at alpha = 1/255, sqrt(2 ln 255) = 3.33 sigma for
/// opacity 1; bbox3sigma at 3).
inline constexpr double kChunkSigmas = 3.34;

/// Pixels of margin around the Jacobian clamp region in the chunk test: the low-pass blur
/// widens a footprint by at most 3.34 sqrt(0.3) = 1.83 px, and footprints in the partial
/// tiles past the right and bottom image edge (< 16 px) still join those tiles' lists.
inline constexpr double kChunkMarginPx = 18.0;

}  // namespace catgs
