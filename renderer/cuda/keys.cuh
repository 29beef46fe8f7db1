// keys: the tile id of each tile-Gaussian pair (16 or 32 bits, tile_key.cuh) and its Gaussian,
// emitted at each Gaussian's scanned offset, Gaussians in depth order (depth_order, sort.cuh),
// so that the sort need only order tiles: the CPU's (tile | depth) keys (stages/keys.hpp) in
// effect. rekey is the cached frames' keys, regrouping the key frame's pairs in the depth order
// of the current pose. When a frame's pairs pass the pair budget it is cut into bands of tile
// rows (band_rows), and count_band recounts each band before its scan.
#pragma once

#include <cuda_runtime_api.h>

#include <cstdint>
#include <vector>

#include "catgs/stages/culling.hpp"
#include "catgs/stages/project.hpp"
#include "catgs/stages/tiles.hpp"
#include "catgs/stages/view.hpp"
#include "kernel_common.cuh"
#include "tile_key.cuh"

namespace catgs::cuda {

template <typename T>
struct KeysArgs {
    DeviceSceneView scene;
    ChunkSpace space;
    const View<T>* views;  // the window's poses
    int window;
    Culling culling;
    T guard;
    const Projected<T>* projected;
    const std::uint64_t* touched;
    /// The slots with pairs in depth order (depth_order), `ordered` of them, and where each
    /// one's keys go: offsets[k] belongs to the k-th slot of the order.
    const std::uint64_t* offsets;
    const std::uint32_t* order;
    std::uint64_t ordered;
    /// When set, each slot's first pair's position (the pairs are kept for cached frames).
    std::uint64_t* emission_offset;
    TileRows rows;           // the band's tile rows (all of them when not banded)
    bool band;               // banded: one pose, whose geometry preprocess stored
    bool reprojected;        // the window lowered the near plane (PreprocessArgs::reproject_actual)
    std::uint64_t capacity;  // bounds every write
    TileKeys keys;           // tile ids
    std::uint32_t* values;
    /// One pose: a Gaussian with more pairs than this is emitted by its whole warp, a tile row a
    /// lane, in the same slots (CudaLimits::keys_thread_pairs).
    std::uint64_t thread_pairs;
};

template <typename T>
void keys(const KeysArgs<T>& args, cudaStream_t stream);

/// The cached Gaussians' depths at the current pose, by slot, for depth_order.
template <typename T>
struct RekeyDepthArgs {
    ChunkSpace space;               // the key frame's
    const std::uint64_t* touched;   // the key frame's counts: 0 = not cached
    const Projected<T>* projected;  // at the current pose (reproject)
    float* depth;
};

template <typename T>
void rekey_depth(const RekeyDepthArgs<T>& args, cudaStream_t stream);

template <typename T>
struct RekeyArgs {
    ChunkSpace space;
    const std::uint64_t* touched;          // the key frame's counts
    const std::uint32_t* order;            // the cached slots in depth order at the current pose
    std::uint64_t ordered;                 // how many (those with pairs)
    const std::uint64_t* offsets;          // by rank: where each slot's pairs go
    const std::uint64_t* emission_offset;  // by slot: where they are among the emitted pairs
    TileKeys emitted_tiles;                // the key frame's pairs' tiles in emission order
    const Projected<T>* projected;         // at the current pose (reproject)
    View<T> view;
    Culling culling;
    TileKeys keys;  // tile ids (parked_tile when the current pose leaves the tile), of emitted_tiles' width
    std::uint32_t* values;
};

template <typename T>
void rekey(const RekeyArgs<T>& args, cudaStream_t stream);

template <typename T>
struct CountBandArgs {
    ChunkSpace space;
    const Projected<T>* projected;
    const std::uint64_t* visible;  // the full-frame counts: 0 = in no list
    View<T> view;
    Culling culling;
    TileRows rows;
    std::uint64_t* touched;
};

template <typename T>
void count_band(const CountBandArgs<T>& args, cudaStream_t stream);

/// The bands of tile rows for a frame of `total` pairs over a budget of `budget`: about twice
/// as many as the budget asks for, so that uneven rows still fit.
std::vector<TileRows> band_rows(std::uint64_t total, std::uint64_t budget, int tiles_y);

}  // namespace catgs::cuda
