// Which tiles' lists a Gaussian joins: the culling mode, an option of every frame. Kept apart
// from the tile math (stages/tiles.hpp) so that the options can name it without pulling that in.
#pragma once

#include <string>

namespace catgs {

enum class Culling : int {
    /// Every visible Gaussian is evaluated at every pixel: one list serves all tiles.
    /// The ground truth for tests; cost grows with Gaussians x pixels.
    exact = 0,
    /// graphdeco's square of tiles around the 3-sigma circle of the major axis.
    bbox3sigma = 1,
    /// The ellipse where sigma * exp(-q/2) reaches 1/255 (FlashGS, gsplat), with an exact
    /// ellipse-tile test: it drops only pairs whose every pixel has alpha < 1/255.
    opacity_aware = 2,
};

/// Parses "exact", "bbox3sigma", "opacity-aware"; throws catgs::Error listing them otherwise.
Culling parse_culling(const std::string& name);
const char* culling_name(Culling culling);

}  // namespace catgs
