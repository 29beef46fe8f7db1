// The device buffers of one CUDA renderer, grouped by what their size follows: the window of
// poses, the scene's chunks, its Gaussians, the frame's tile-Gaussian pairs, its tiles and
// its pixels. Every one is a grow-only arena (device_buffer.hpp), so a stream of frames
// settles after a few frames and then allocates nothing.
#pragma once

#include <cuda_runtime_api.h>

#include <cstddef>
#include <cstdint>

#include "catgs/constants.hpp"
#include "catgs/stages/blend.hpp"
#include "catgs/stages/project.hpp"
#include "catgs/stages/split.hpp"
#include "catgs/stages/view.hpp"
#include "cuda_check.hpp"
#include "device_buffer.hpp"
#include "kernel_common.cuh"
#include "occlusion.cuh"
#include "tile_key.cuh"

namespace catgs::cuda {

/// Per window: the poses a key frame projects against, and the device counters.
template <typename T>
struct WindowBuffers {
    DeviceArray<View<T>> views;
    DeviceArray<Counters> counters;

    std::size_t bytes() const { return views.bytes() + counters.bytes(); }
};

/// Per chunk of the scene: chunk culling's flags and the compacted list of visible chunks.
struct ChunkBuffers {
    DeviceArray<std::uint8_t> flags;      // 1 = some pose may see the chunk
    DeviceArray<std::uint32_t> selected;  // the visible chunks, in scene order

    std::size_t bytes() const { return flags.bytes() + selected.bytes(); }
};

/// Per Gaussian: the projection by Gaussian index, and the counts, depths and offsets by slot
/// of the chunk-compacted index space (ChunkSpace).
template <typename T>
struct GaussianBuffers {
    DeviceArray<Projected<T>> projected;  // preprocess: at the actual pose
    DeviceArray<std::uint64_t> visible;   // band path: full-frame tile counts
    DeviceArray<std::uint64_t> touched;   // tile counts for the current pass, with a trailing 0
    DeviceArray<float> sort_depth;        // preprocess: the depth keys sort by
    DeviceArray<std::uint8_t> scan_temp;  // CUB's DeviceScan
    /// keys: where each slot's pairs start among a key frame's pairs in emission order (cached
    /// frames that re-sort regroup them from there).
    DeviceArray<std::uint64_t> emission_offset;

    std::size_t bytes() const {
        return projected.bytes() + visible.bytes() + touched.bytes() + sort_depth.bytes() + scan_temp.bytes() +
               emission_offset.bytes();
    }
};

/// A CUDA event made on first use (no timing): a point the host waits for.
class HostWaitEvent {
public:
    HostWaitEvent() = default;
    HostWaitEvent(const HostWaitEvent&) = delete;
    HostWaitEvent& operator=(const HostWaitEvent&) = delete;
    ~HostWaitEvent() {
        if (event_) cudaEventDestroy(event_);  // not checked: runs in destructors
    }
    cudaEvent_t get() {
        if (!event_) CATGS_CUDA_CHECK(cudaEventCreateWithFlags(&event_, cudaEventDisableTiming));
        return event_;
    }

private:
    cudaEvent_t event_ = nullptr;
};

/// The slots with pairs in depth order (depth_order, sort.cuh): their selection in slot order
/// (a key frame's, which its cached frames keep), then the slots front to back,
/// double-buffered for the sort, and their pair counts and scanned offsets in that order.
struct DepthOrderBuffers {
    DeviceArray<std::uint32_t> with_pairs;  // the slots with pairs, ascending
    HostWaitEvent totals_read;              // the key frame's ListTotals are in host memory
    DeviceArray<std::uint8_t> select_temp;
    std::uint64_t ranked = 0;                   // the selected count, read back (ListTotals)
    DeviceArray<std::uint32_t> keys[2];         // depth bits
    DeviceArray<std::uint32_t> slots[2];        // slot indices
    int current = 0;                            // which of keys/slots holds the order
    DeviceArray<std::uint64_t> ranked_offsets;  // where the k-th nearest slot's pairs go; the total last
    DeviceArray<std::uint8_t> sort_temp;

    const std::uint32_t* order() const { return slots[current].data(); }
    std::size_t bytes() const {
        return with_pairs.bytes() + select_temp.bytes() + keys[0].bytes() + keys[1].bytes() + slots[0].bytes() +
               slots[1].bytes() + ranked_offsets.bytes() + sort_temp.bytes();
    }
};

/// Pair tile ids as narrow as the grid allows (tile_key.cuh): a typed view of raw device bytes,
/// so one arena serves either width.
class TileKeyArray {
public:
    bool reserve(std::size_t count, TileKeyWidth width, cudaStream_t stream) {
        return bytes_.reserve(count * tile_key_bytes(width), stream);
    }
    TileKeys keys(TileKeyWidth width) const { return TileKeys{bytes_.data(), width}; }
    std::size_t bytes() const { return bytes_.capacity(); }

private:
    DeviceBytes bytes_;
};

/// Per tile-Gaussian pair: its tile (the sort key: the pairs are emitted front to back, so
/// the tile alone orders them, sort.cuh) and Gaussian, double-buffered for the sort, and a key
/// frame's tiles in emission order, which cached frames that re-sort re-key from (their values
/// follow from GaussianBuffers::emission_offset). `width` is the frame's tile key width, which
/// a window's frames share (they have the key frame's resolution).
struct PairBuffers {
    TileKeyArray tiles[2];
    DeviceArray<std::uint32_t> values[2];
    int current = 0;  // which of tiles/values holds the sorted pairs
    TileKeyWidth width = TileKeyWidth::bits32;
    TileKeyArray emitted_tiles;
    DeviceArray<std::uint8_t> sort_temp;  // CUB's DeviceRadixSort

    /// The tile ids of tiles[which] and of emitted_tiles, as `width` reads them.
    TileKeys tile_keys(int which) const { return tiles[which].keys(width); }
    TileKeys emitted_keys() const { return emitted_tiles.keys(width); }
    TileKeys sorted_tiles() const { return tile_keys(current); }
    std::size_t bytes() const {
        return tiles[0].bytes() + tiles[1].bytes() + values[0].bytes() + values[1].bytes() + emitted_tiles.bytes() +
               sort_temp.bytes();
    }
};

/// Per tile, and per task of the task list: ranges, split slots and labels.
struct TileBuffers {
    DeviceArray<std::uint64_t> range_begin, range_end;  // ranges
    DeviceArray<std::uint32_t> split_slot;              // split: first partial slot of a split tile, or kNoSlot
    DeviceArray<unsigned int> merge_tickets;            // rasterize: a split tile's sub-tasks done (merge.cuh)
    DeviceArray<TaskLabel> labels;                      // split: the extra sub-tasks
    DeviceArray<std::uint32_t> heavy_tiles;             // split: the lists that run first (runs_first)
    DeviceArray<std::uint8_t> runs_first;               // split: per tile, 1 when listed in heavy_tiles

    std::size_t bytes() const {
        return range_begin.bytes() + range_end.bytes() + split_slot.bytes() + merge_tickets.bytes() + labels.bytes() +
               heavy_tiles.bytes() + runs_first.bytes();
    }
};

/// Per pixel: the sub-tasks' partial (R, A) and the finished image (a partial frame's R in
/// image_float, with its A and stops).
template <typename T>
struct PixelBuffers {
    DeviceArray<Partial<T>> partials;      // rasterize: sub-task (R, A), merged by the tile's last (merge.cuh)
    DeviceArray<std::uint8_t> image_rgb8;  // rasterize / merge
    DeviceArray<float> image_float;
    DeviceArray<float> image_transmittance;  // render_partial
    DeviceArray<std::uint8_t> image_stopped;

    std::size_t bytes() const {
        return partials.bytes() + image_rgb8.bytes() + image_float.bytes() + image_transmittance.bytes() +
               image_stopped.bytes();
    }
};

template <typename T>
struct FrameBuffers {
    WindowBuffers<T> window;
    ChunkBuffers chunks;
    GaussianBuffers<T> gaussians;
    DepthOrderBuffers depth;
    PairBuffers pairs;
    TileBuffers tiles;
    PixelBuffers<T> pixels;
    OcclusionBuffers occlusion;  // per tile, across frames

    std::size_t bytes() const {
        return window.bytes() + chunks.bytes() + gaussians.bytes() + depth.bytes() + pairs.bytes() + tiles.bytes() +
               pixels.bytes() + occlusion.bytes();
    }
};

/// Pinned host memory for one read-back: `reserve` reallocates to exactly what is asked when
/// it is short. Mapped into the device as well, so that a kernel may write into it directly
/// (PixelOutputs::heavy_rgb8) instead of a copy engine after it.
template <typename V>
class PinnedArray {
public:
    PinnedArray() = default;
    PinnedArray(const PinnedArray&) = delete;
    PinnedArray& operator=(const PinnedArray&) = delete;
    ~PinnedArray() { cudaFreeHost(data_); }  // not checked: runs in destructors

    void reserve(std::size_t count) {
        if (bytes_ >= count * sizeof(V)) return;
        cudaFreeHost(data_);
        data_ = device_ = nullptr;
        bytes_ = 0;  // nothing held should the allocation throw
        CATGS_CUDA_CHECK(cudaHostAlloc(&data_, count * sizeof(V), cudaHostAllocMapped));
        bytes_ = count * sizeof(V);
        CATGS_CUDA_CHECK(cudaHostGetDevicePointer(reinterpret_cast<void**>(&device_), data_, 0));
    }
    V* data() const { return data_; }      // the host's address
    V* device() const { return device_; }  // the kernels'

private:
    V* data_ = nullptr;
    V* device_ = nullptr;
    std::size_t bytes_ = 0;
};

/// The pinned host side of the frame's read-backs: the window's poses on their way up, the
/// pass totals, the frame's counters and the image on their way down.
template <typename T>
struct HostStaging {
    PinnedArray<View<T>> views;
    PinnedArray<std::uint64_t> total;  // a band's scan total
    PinnedArray<ListTotals> lists;     // a key frame's totals, read back before its depth sort
    PinnedArray<Counters> counters;
    PinnedArray<std::uint8_t> rgb8;  // copy_out
    PinnedArray<float> rgb_float;
    PinnedArray<float> transmittance;  // copy_out of a partial frame
    PinnedArray<std::uint8_t> stopped;
    PinnedArray<std::uint8_t> heavy_rgb8;  // rasterize's heavy lists (PixelOutputs::heavy_rgb8)
    PinnedArray<std::uint32_t> heavy_tiles;
};

}  // namespace catgs::cuda
