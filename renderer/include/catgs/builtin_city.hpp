// The built-in default scene: a deterministic procedural UAV city block (z is up, metres).
// A ground plane with colour variation and roads, buildings with facades and roofs, trees as
// clusters of larger semi-transparent Gaussians; SH degree 3 with real view-dependent terms.
#pragma once

#include <cstdint>
#include <string>

#include "catgs/progress.hpp"
#include "catgs/scene.hpp"

namespace catgs {

struct CityParams {
    std::uint64_t gaussians = 1'000'000;  ///< 10^4 .. 2*10^7
    std::uint64_t seed = 1;
};

inline constexpr std::uint64_t kCityMinGaussians = 10'000;
inline constexpr std::uint64_t kCityMaxGaussians = 20'000'000;

/// Parses "builtin:city", "builtin:city?gaussians=2000000&seed=1". Throws catgs::Error that
/// names the bad key or value (unknown generator, unknown key, out-of-range count, ...).
CityParams parse_city_spec(const std::string& spec);

/// Generates exactly params.gaussians Gaussians; the same params give bit-identical scenes
/// on every machine (no libm; built with -ffp-contract=off). Positions are relative to
/// scene.origin (the block centre). Throws catgs::Error for counts outside [10^4, 2*10^7].
Scene make_city(const CityParams& params, const Progress& progress = {});

namespace detail {
/// make_city with an explicit worker count (0 = all cores): tests show the result does not
/// depend on it.
Scene make_city_with_threads(const CityParams& params, const Progress& progress, unsigned threads);
}  // namespace detail

}  // namespace catgs
