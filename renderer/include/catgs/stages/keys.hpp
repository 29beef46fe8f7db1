// The sort key of a tile-Gaussian pair: tile id in the high 32 bits, the view depth's float bits
// in sort order in the low 32, so that one radix sort orders the pairs by tile and then front to back.
// Both backends emit, park and sort keys through these helpers.
#pragma once

#include <cstdint>
#include <cstring>

#include "catgs/hd.hpp"

namespace catgs {

/// The depth half of a key: the float's bits, in sort order (ordered_depth_bits).
inline constexpr int kSortKeyDepthBits = 32;

/// A depth's bits in an order that sorts as the depth does: the sign bit set on positive floats,
/// every bit flipped on negative ones, so negative depths sort first and nearest-first among
/// themselves. A frame's own depths are > near plane > 0, but a cached window keys its
/// Gaussians by their depth at the key pose, where one that enters the view later may lie
/// behind the camera (cpu_renderer.cpp, preprocess.cu).
CATGS_INLINE std::uint32_t ordered_depth_bits(float depth) {
#if defined(__CUDA_ARCH__)
    const std::uint32_t bits = __float_as_uint(depth);
#else
    std::uint32_t bits;
    static_assert(sizeof(bits) == sizeof(depth));
    std::memcpy(&bits, &depth, sizeof(bits));
#endif
    return (bits & 0x80000000u) ? ~bits : (bits | 0x80000000u);
}

/// The depth a key holds: ordered_depth_bits undone.
CATGS_INLINE float depth_of_key(std::uint64_t key) {
    const std::uint32_t ordered = static_cast<std::uint32_t>(key);
    const std::uint32_t bits = (ordered & 0x80000000u) ? (ordered & 0x7fffffffu) : ~ordered;
#if defined(__CUDA_ARCH__)
    return __uint_as_float(bits);
#else
    float depth;
    std::memcpy(&depth, &bits, sizeof(depth));
    return depth;
#endif
}

CATGS_INLINE std::uint64_t make_sort_key(std::uint32_t tile, float depth) {
    return (static_cast<std::uint64_t>(tile) << kSortKeyDepthBits) | ordered_depth_bits(depth);
}

CATGS_INLINE std::uint32_t key_tile(std::uint64_t key) {
    return static_cast<std::uint32_t>(key >> kSortKeyDepthBits);
}

/// Cached frames park the pairs the current pose does not need at tile id `tiles`: past every
/// real tile, so they sort last and no range covers them (sort_key_tile_bits counts it).
CATGS_INLINE std::uint32_t parked_tile(std::uint32_t tiles) {
    return tiles;
}

/// How many bits the tile half of a key needs on a grid of `tiles` tiles: ids run over
/// 0..tiles, the parked tile included, so the bit width of `tiles`. A sort need only look at
/// kSortKeyDepthBits + this many low bits.
CATGS_HD constexpr int sort_key_tile_bits(std::uint64_t tiles) {
    int bits = 0;
    while (tiles) {
        ++bits;
        tiles >>= 1;
    }
    return bits;
}

/// The GPU's pairs carry their tile id alone (sort.cuh), in 16 bits while every id, the parked
/// one included, fits there: grids of up to 65535 tiles (4K is 32400), which halves the bytes
/// the tile sort moves a key. Larger grids take 32 bits.
inline constexpr int kNarrowTileKeyBits = 16;

CATGS_HD constexpr bool narrow_tile_keys(std::uint64_t tiles) {
    return sort_key_tile_bits(tiles) <= kNarrowTileKeyBits;
}

}  // namespace catgs
