// The width of the pairs' tile ids on the GPU (narrow_tile_keys, stages/keys.hpp): 16 bits on
// grids of up to 65535 tiles, else 32. keys and rekey write them, sort orders them, ranges
// reads them; each launches the instance of the frame's width (with_tile_key).
#pragma once

#include <cstddef>
#include <cstdint>

#include "catgs/stages/keys.hpp"

namespace catgs::cuda {

enum class TileKeyWidth { bits16, bits32 };

inline TileKeyWidth tile_key_width(std::uint64_t tiles) {
    return narrow_tile_keys(tiles) ? TileKeyWidth::bits16 : TileKeyWidth::bits32;
}

inline std::size_t tile_key_bytes(TileKeyWidth width) {
    return width == TileKeyWidth::bits16 ? sizeof(std::uint16_t) : sizeof(std::uint32_t);
}

/// Device memory holding tile ids of one width.
struct TileKeys {
    void* data;
    TileKeyWidth width;
};

/// `keys` as ids of type Key (the width's type: with_tile_key).
template <typename Key>
Key* key_data(const TileKeys& keys) {
    return static_cast<Key*>(keys.data);
}

/// Calls `launch` with a value of the tile id type of `width`, so a generic lambda can name
/// it (decltype) in the kernel instance it launches.
template <typename Launch>
void with_tile_key(TileKeyWidth width, Launch&& launch) {
    if (width == TileKeyWidth::bits16)
        launch(std::uint16_t{});
    else
        launch(std::uint32_t{});
}

}  // namespace catgs::cuda
