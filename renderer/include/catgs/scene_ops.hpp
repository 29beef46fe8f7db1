// Scene transformations used to build benchmark scenes from real captures.
#pragma once

#include <string>

#include "catgs/scene.hpp"

namespace catgs {

/// Per-axis percentile bounds of the positions (world coordinates), e.g. 0.01 and 0.99.
Bounds percentile_bounds(const Scene& scene, double low, double high);

/// Replicates a scene in an nx x ny grid over the two horizontal axes (those other than
/// `up_axis`, 0..2). Each copy keeps only the Gaussians inside the scene's 1st..99th
/// percentile box on those axes (its cell) and is offset by that box's extent, so the copies
/// tile the plane without overlapping. Throws catgs::Error for nx or ny < 1.
Scene replicate_grid(const Scene& scene, int nx, int ny, int up_axis);

/// Reorders the Gaussians along a Morton (Z-order) curve over the bounds of their means and
/// cuts that order into Scene::chunks of kChunkGaussians: chunks are then compact in space,
/// so that chunk-level culling skips whole off-screen regions (stages/chunks.hpp). The order
/// is a stable sort of the Morton codes: Gaussians in one cell keep their relative order.
/// Gaussians with a non-finite position go last.
void partition_into_chunks(Scene& scene);

/// Drops the SH coefficients above `degree` (0..3): a scene rendered at degree 0 evaluates only
/// the DC term, a view-independent colour. The image equals that of the scene with those
/// coefficients set to zero. A degree at or above the scene's changes nothing; a negative one
/// throws catgs::Error.
void truncate_sh(Scene& scene, int degree);

/// Parses "3x3" into (3, 3); throws catgs::Error naming the text otherwise.
std::pair<int, int> parse_grid(const std::string& text);

/// Parses "x", "y", "z", "-x", "-y", "-z" into the axis index 0..2 (the sign is ignored here).
int parse_up_axis(const std::string& text);

}  // namespace catgs
