#include "cuda_renderer.hpp"

#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_scan.cuh>

#include <algorithm>
#include <cstring>
#include <vector>

#include "catgs/stages/blend.hpp"
#include "catgs/stages/project.hpp"
#include "catgs/stages/tiles.hpp"
#include "catgs/stages/view.hpp"
#include "cuda_check.hpp"
#include "device_buffer.hpp"

namespace catgs::cuda {
namespace {

constexpr int kPreprocessThreads = 256;  // one Gaussian per thread; 256 keeps SM occupancy high
constexpr int kTilePixels = kTileSize * kTileSize;  // one thread per pixel of a tile

/// Bytes of device memory one tile-Gaussian pair needs: key + value, twice (sort buffers).
constexpr std::uint64_t kBytesPerPair = 2 * (sizeof(std::uint64_t) + sizeof(std::uint32_t));
/// Share of free device memory the automatic pair budget may take (the rest stays for the
/// scene, other renderers and CUB's temporary storage).
constexpr double kAutoPairMemoryShare = 0.25;

struct DeviceSceneView {
    const float* positions;
    const float* scales;
    const float* rotations;
    const float* opacities;
    const float* sh;
    int sh_degree;
    std::uint64_t count;
};

/// What the rasterizer reads of one Gaussian, staged in shared memory.
template <typename T>
struct Splat {
    Vec2<T> mean;
    Vec3<T> conic;
    T opacity;
    Vec3<T> colour;
};

int bit_width(std::uint64_t v) {
    int bits = 0;
    while (v) {
        ++bits;
        v >>= 1;
    }
    return bits;
}

unsigned blocks_for(std::uint64_t n, int threads) { return static_cast<unsigned>((n + threads - 1) / threads); }

// Stage 1: project and count tiles over the whole frame. touched[i] = 0 marks a culled one;
// `visible_count` gets one atomic add per block.
template <typename T>
__global__ void preprocess_kernel(DeviceSceneView scene, View<T> view, Culling culling, Projected<T>* projected,
                                  std::uint64_t* touched, unsigned long long* visible_count) {
    const std::uint64_t i = static_cast<std::uint64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
    bool visible = false;
    if (i < scene.count) {
        std::uint32_t tiles = 0;
        const std::size_t sh_stride = 3u * static_cast<std::size_t>(sh_coefficient_count(scene.sh_degree));
        const GaussianRef g{scene.positions + 3 * i, scene.scales + 3 * i, scene.rotations + 4 * i,
                            scene.opacities[i], scene.sh + sh_stride * i, scene.sh_degree};
        Projected<T> p;
        if (project_gaussian(g, view, p)) {
            projected[i] = p;
            tiles = for_each_touched_tile(p, culling, view, [](std::uint32_t) {});
        }
        touched[i] = tiles;
        visible = tiles > 0;
    }
    const int block_visible = __syncthreads_count(visible);
    if (threadIdx.x == 0 && block_visible > 0) atomicAdd(visible_count, static_cast<unsigned long long>(block_visible));
}

// Count within a band of tile rows (overflow path only), through the same predicate.
template <typename T>
__global__ void count_band_kernel(std::uint64_t n, const Projected<T>* projected, const std::uint64_t* visible,
                                  View<T> view, Culling culling, TileRows rows, std::uint64_t* touched) {
    const std::uint64_t i = static_cast<std::uint64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
    if (i >= n) return;
    touched[i] = visible[i] == 0 ? 0 : for_each_touched_tile(projected[i], culling, view, [](std::uint32_t) {}, rows);
}

// Stage 3: keys at each Gaussian's offset, in Gaussian order, so that the stable sort keeps
// index order for equal depths. `capacity` bounds every write.
template <typename T>
__global__ void emit_kernel(std::uint64_t n, const Projected<T>* projected, const std::uint64_t* touched,
                            const std::uint64_t* offsets, View<T> view, Culling culling, TileRows rows,
                            std::uint64_t capacity, std::uint64_t* keys, std::uint32_t* values) {
    const std::uint64_t i = static_cast<std::uint64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
    if (i >= n || touched[i] == 0) return;
    std::uint64_t slot = offsets[i];
    const std::uint64_t end = min(slot + touched[i], capacity);
    const float depth = static_cast<float>(projected[i].depth);
    for_each_touched_tile(
        projected[i], culling, view,
        [&](std::uint32_t tile) {
            if (slot < end) {
                keys[slot] = make_sort_key(tile, depth);
                values[slot] = static_cast<std::uint32_t>(i);
            }
            ++slot;
        },
        rows);
}

// Stage 5: tile ranges; ids beyond the grid are ignored rather than written (defence against
// a corrupted key, the failure mode of gaussian-splatting#781).
__global__ void ranges_kernel(std::uint64_t n, const std::uint64_t* keys, std::uint32_t tiles,
                              std::uint64_t* range_begin, std::uint64_t* range_end) {
    const std::uint64_t i = static_cast<std::uint64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
    if (i >= n) return;
    const std::uint32_t tile = key_tile(keys[i]);
    if (tile >= tiles) return;
    if (i == 0 || key_tile(keys[i - 1]) != tile) range_begin[tile] = i;
    if (i + 1 == n || key_tile(keys[i + 1]) != tile) range_end[tile] = i + 1;
}

// Stage 6: one block per tile of the band, one thread per pixel, Gaussians staged through
// shared memory a batch at a time; the block stops when all its pixels are done.
template <typename T>
__global__ void __launch_bounds__(kTilePixels)
    rasterize_kernel(const std::uint64_t* range_begin, const std::uint64_t* range_end, bool shared_list,
                     std::uint64_t list_size, const std::uint32_t* values, const Projected<T>* projected, View<T> view,
                     int first_row, Vec3<T> background, std::uint8_t* out_rgb8, float* out_float) {
    __shared__ Splat<T> batch[kTilePixels];
    const int tile_x = blockIdx.x, tile_y = blockIdx.y + first_row;
    const int tile = tile_y * view.tiles_x + tile_x;
    const int rank = threadIdx.y * kTileSize + threadIdx.x;
    const int x = tile_x * kTileSize + threadIdx.x, y = tile_y * kTileSize + threadIdx.y;
    const bool inside = x < view.width && y < view.height;
    const std::uint64_t begin = shared_list ? 0 : range_begin[tile];
    const std::uint64_t end = shared_list ? list_size : range_end[tile];
    const T px = static_cast<T>(x) + T(0.5), py = static_cast<T>(y) + T(0.5);

    PixelAccumulator<T> acc;
    acc.done = !inside;
    for (std::uint64_t start = begin; start < end; start += kTilePixels) {
        if (__syncthreads_count(acc.done) == kTilePixels) break;
        const std::uint64_t idx = start + rank;
        if (idx < end) {
            const Projected<T>& p = projected[values[idx]];
            batch[rank] = Splat<T>{p.mean, p.conic, p.opacity, p.colour};
        }
        __syncthreads();
        const int count = end - start < kTilePixels ? static_cast<int>(end - start) : kTilePixels;
        for (int j = 0; j < count && !acc.done; ++j) {
            const Splat<T>& s = batch[j];
            blend_gaussian(acc, s.mean, s.conic, s.opacity, s.colour, px, py);
        }
    }
    if (!inside) return;
    const Vec3<T> c = finish_pixel(acc, background);
    const std::size_t o = 3 * (static_cast<std::size_t>(y) * view.width + x);
    if (out_rgb8) {
        out_rgb8[o] = quantize_8bit(c.x);
        out_rgb8[o + 1] = quantize_8bit(c.y);
        out_rgb8[o + 2] = quantize_8bit(c.z);
    }
    if (out_float) {
        out_float[o] = static_cast<float>(c.x);
        out_float[o + 1] = static_cast<float>(c.y);
        out_float[o + 2] = static_cast<float>(c.z);
    }
}

/// Device events around the stages of one frame.
enum Stage { kStart, kPreprocess, kScan, kBandCount, kBandScan, kEmit, kSort, kRanges, kRasterize, kCopy, kStageCount };

float* alloc_copy(const std::vector<float>& host, cudaStream_t stream, std::size_t& bytes) {
    float* d = nullptr;
    const std::size_t n = std::max<std::size_t>(host.size(), 1) * sizeof(float);
    CATGS_CUDA_CHECK(cudaMalloc(&d, n));
    if (!host.empty())
        CATGS_CUDA_CHECK(cudaMemcpyAsync(d, host.data(), host.size() * sizeof(float), cudaMemcpyHostToDevice, stream));
    bytes += n;
    return d;
}

}  // namespace

bool device_available(std::string* reason) {
    int count = 0;
    const cudaError_t status = cudaGetDeviceCount(&count);
    if (status != cudaSuccess || count == 0) {
        if (reason) *reason = status != cudaSuccess ? cudaGetErrorString(status) : "no CUDA device";
        cudaGetLastError();  // clear the sticky-free error state for later calls
        return false;
    }
    return true;
}

DeviceScene::DeviceScene(const Scene& scene, cudaStream_t stream)
    : count_(scene.count()), sh_degree_(scene.sh_degree), origin_(scene.origin) {
    scene.check_consistent("scene upload");
    try {
        positions_ = alloc_copy(scene.positions, stream, bytes_);
        scales_ = alloc_copy(scene.scales, stream, bytes_);
        rotations_ = alloc_copy(scene.rotations, stream, bytes_);
        opacities_ = alloc_copy(scene.opacities, stream, bytes_);
        sh_ = alloc_copy(scene.sh, stream, bytes_);
        CATGS_CUDA_CHECK(cudaStreamSynchronize(stream));
    } catch (...) {
        for (float* p : {positions_, scales_, rotations_, opacities_, sh_}) cudaFree(p);
        throw;
    }
}

DeviceScene::~DeviceScene() {
    for (float* p : {positions_, scales_, rotations_, opacities_, sh_}) cudaFree(p);
}

template <typename T>
struct CudaRenderer<T>::Impl {
    cudaStream_t stream = nullptr;
    bool own_stream = false;
    CudaLimits limits;
    std::shared_ptr<const DeviceScene> scene;
    cudaEvent_t events[kStageCount] = {};

    // Arenas, one per stage buffer.
    DeviceArray<Projected<T>> projected;   // preprocess
    DeviceArray<std::uint64_t> visible;    // preprocess: full-frame tile counts (band path keeps them)
    DeviceArray<std::uint64_t> touched;    // count for the current pass, with a trailing 0
    DeviceArray<unsigned long long> visible_count;  // preprocess: Gaussians with tiles
    DeviceArray<std::uint64_t> offsets;    // scan: exclusive sum; offsets[n] = pass total
    DeviceArray<std::uint8_t> scan_temp;
    DeviceArray<std::uint64_t> keys[2];    // emit + sort (double buffer)
    DeviceArray<std::uint32_t> values[2];
    DeviceArray<std::uint8_t> sort_temp;
    DeviceArray<std::uint64_t> range_begin, range_end;  // ranges
    DeviceArray<std::uint8_t> image_rgb8;  // rasterize
    DeviceArray<float> image_float;
    std::uint64_t* host_total = nullptr;   // pinned, for the one read-back per pass: total, visible
    std::uint8_t* host_rgb8 = nullptr;     // pinned staging for copy-out
    float* host_float = nullptr;
    std::size_t host_rgb8_bytes = 0, host_float_bytes = 0;

    std::size_t arena_bytes() const {
        return projected.bytes() + visible.bytes() + touched.bytes() + offsets.bytes() + scan_temp.bytes() +
               keys[0].bytes() + keys[1].bytes() + values[0].bytes() + values[1].bytes() + sort_temp.bytes() +
               range_begin.bytes() + range_end.bytes() + image_rgb8.bytes() + image_float.bytes() +
               visible_count.bytes();
    }

    std::uint64_t pair_budget() {
        if (limits.max_pairs == 0) {
            std::size_t free_bytes = 0, total_bytes = 0;
            CATGS_CUDA_CHECK(cudaMemGetInfo(&free_bytes, &total_bytes));
            limits.max_pairs = std::max<std::uint64_t>(
                1, static_cast<std::uint64_t>(kAutoPairMemoryShare * static_cast<double>(free_bytes) / kBytesPerPair));
        }
        return limits.max_pairs;
    }

    /// Exclusive scan of touched[0..n] into offsets; returns the pass total (one read-back).
    std::uint64_t scan(std::uint64_t n) {
        std::size_t temp_bytes = 0;
        CATGS_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(nullptr, temp_bytes, touched.data(), offsets.data(),
                                                       static_cast<std::int64_t>(n + 1), stream));
        scan_temp.reserve(temp_bytes, stream);
        CATGS_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(scan_temp.data(), temp_bytes, touched.data(), offsets.data(),
                                                       static_cast<std::int64_t>(n + 1), stream));
        CATGS_CUDA_CHECK(cudaMemcpyAsync(host_total, offsets.data() + n, sizeof(std::uint64_t),
                                         cudaMemcpyDeviceToHost, stream));
        CATGS_CUDA_CHECK(cudaMemcpyAsync(host_total + 1, visible_count.data(), sizeof(std::uint64_t),
                                         cudaMemcpyDeviceToHost, stream));
        CATGS_CUDA_CHECK(cudaStreamSynchronize(stream));
        return *host_total;
    }
};

template <typename T>
CudaRenderer<T>::CudaRenderer(cudaStream_t stream, CudaLimits limits) : impl_(std::make_unique<Impl>()) {
    impl_->limits = limits;
    if (stream) {
        impl_->stream = stream;
    } else {
        CATGS_CUDA_CHECK(cudaStreamCreateWithFlags(&impl_->stream, cudaStreamNonBlocking));
        impl_->own_stream = true;
    }
    for (auto& e : impl_->events) CATGS_CUDA_CHECK(cudaEventCreate(&e));
    CATGS_CUDA_CHECK(cudaMallocHost(&impl_->host_total, 2 * sizeof(std::uint64_t)));
    impl_->visible_count.reserve(1, impl_->stream);
}

template <typename T>
CudaRenderer<T>::~CudaRenderer() {
    if (!impl_) return;
    cudaStreamSynchronize(impl_->stream);
    for (auto& e : impl_->events) cudaEventDestroy(e);
    cudaFreeHost(impl_->host_total);
    cudaFreeHost(impl_->host_rgb8);
    cudaFreeHost(impl_->host_float);
    if (impl_->own_stream) cudaStreamDestroy(impl_->stream);
}

template <typename T>
void CudaRenderer<T>::set_scene(std::shared_ptr<const DeviceScene> scene) {
    impl_->scene = std::move(scene);
}

template <typename T>
void CudaRenderer<T>::set_limits(CudaLimits limits) {
    impl_->limits = limits;
}

template <typename T>
cudaStream_t CudaRenderer<T>::stream() const {
    return impl_->stream;
}

template <typename T>
FrameStats CudaRenderer<T>::render(const Camera& camera, const RenderOptions& options, ImageRGB8* rgb8,
                                   ImageF* rgb_float) {
    Impl& m = *impl_;
    if (!m.scene) throw Error("cuda renderer: no scene set");
    validate(camera.intrinsics, "camera '" + camera.name + "'");
    const DeviceScene& scene = *m.scene;
    const View<T> view = make_view<T>(camera, scene.origin(), options.near_plane);
    const std::uint64_t n = scene.count();
    const std::uint64_t tiles = static_cast<std::uint64_t>(view.tiles_x) * view.tiles_y;
    const std::size_t pixels = static_cast<std::size_t>(view.width) * view.height;
    cudaStream_t s = m.stream;
    FrameStats stats;

    // Arenas for this frame's per-Gaussian, per-tile and per-pixel buffers.
    m.projected.reserve(n, s);
    m.visible.reserve(n + 1, s);
    m.touched.reserve(n + 1, s);
    m.offsets.reserve(n + 1, s);
    m.range_begin.reserve(tiles, s);
    m.range_end.reserve(tiles, s);
    if (rgb8) m.image_rgb8.reserve(3 * pixels, s);
    if (rgb_float) m.image_float.reserve(3 * pixels, s);

    const DeviceSceneView sv{scene.positions(), scene.scales(), scene.rotations(), scene.opacities(),
                             scene.sh(),        scene.sh_degree(), n};
    CATGS_CUDA_CHECK(cudaEventRecord(m.events[kStart], s));
    CATGS_CUDA_CHECK(cudaMemsetAsync(m.touched.data() + n, 0, sizeof(std::uint64_t), s));
    CATGS_CUDA_CHECK(cudaMemsetAsync(m.visible_count.data(), 0, sizeof(unsigned long long), s));
    if (n > 0) {
        preprocess_kernel<T><<<blocks_for(n, kPreprocessThreads), kPreprocessThreads, 0, s>>>(
            sv, view, options.culling, m.projected.data(), m.touched.data(), m.visible_count.data());
        CATGS_CUDA_CHECK_LAUNCH("preprocess");
    }
    CATGS_CUDA_CHECK(cudaEventRecord(m.events[kPreprocess], s));
    std::uint64_t total = m.scan(n);
    CATGS_CUDA_CHECK(cudaEventRecord(m.events[kScan], s));
    stats.visible = m.host_total[1];
    stats.pairs = total;

    // Bands: split the tile rows so each band's pairs fit the budget. The full-frame
    // counts are kept in `visible` so each band recounts only its own rows.
    const std::uint64_t budget = m.pair_budget();
    const bool shared_list = options.culling == Culling::exact;
    std::vector<TileRows> bands;
    if (total <= budget || shared_list) {
        if (shared_list && total > budget)
            throw Error("cuda renderer: exact culling needs " + std::to_string(total) +
                        " pairs, more than the pair budget of " + std::to_string(budget));
        bands.push_back({0, view.tiles_y});
    } else {
        const int band_count = static_cast<int>(std::min<std::uint64_t>(view.tiles_y, (total + budget - 1) / budget * 2));
        const int rows_per_band = (view.tiles_y + band_count - 1) / band_count;
        for (int r = 0; r < view.tiles_y; r += rows_per_band) bands.push_back({r, std::min(view.tiles_y, r + rows_per_band)});
        CATGS_CUDA_CHECK(cudaMemcpyAsync(m.visible.data(), m.touched.data(), (n + 1) * sizeof(std::uint64_t),
                                         cudaMemcpyDeviceToDevice, s));
    }
    stats.bands = static_cast<int>(bands.size());
    const int tile_bits = bit_width(tiles);

    float emit_ms = 0, sort_ms = 0, ranges_ms = 0, raster_ms = 0, scan_extra_ms = 0;
    cudaEvent_t* e = m.events;
    for (std::size_t b = 0; b < bands.size(); ++b) {
        const TileRows rows = bands[b];
        std::uint64_t pass_total = total;
        cudaEvent_t pass_start = e[kScan];
        if (bands.size() > 1) {
            CATGS_CUDA_CHECK(cudaEventRecord(e[kBandCount], s));
            if (n > 0) {
                count_band_kernel<T><<<blocks_for(n, kPreprocessThreads), kPreprocessThreads, 0, s>>>(
                    n, m.projected.data(), m.visible.data(), view, options.culling, rows, m.touched.data());
                CATGS_CUDA_CHECK_LAUNCH("count_band");
            }
            pass_total = m.scan(n);
            CATGS_CUDA_CHECK(cudaEventRecord(e[kBandScan], s));
            CATGS_CUDA_CHECK(cudaEventSynchronize(e[kBandScan]));
            float ms = 0;
            CATGS_CUDA_CHECK(cudaEventElapsedTime(&ms, e[kBandCount], e[kBandScan]));
            scan_extra_ms += ms;
            pass_start = e[kBandScan];
            if (pass_total > budget)
                throw Error("cuda renderer: tile rows " + std::to_string(rows.begin) + ".." + std::to_string(rows.end) +
                            " need " + std::to_string(pass_total) + " tile-Gaussian pairs, more than the budget of " +
                            std::to_string(budget) + "; raise the pair budget or lower the resolution");
        }
        // Emit.
        if (pass_total > 0) {
            for (int k = 0; k < 2; ++k) {
                m.keys[k].reserve(pass_total, s);
                m.values[k].reserve(pass_total, s);
            }
            emit_kernel<T><<<blocks_for(n, kPreprocessThreads), kPreprocessThreads, 0, s>>>(
                n, m.projected.data(), m.touched.data(), m.offsets.data(), view, options.culling, rows, pass_total,
                m.keys[0].data(), m.values[0].data());
            CATGS_CUDA_CHECK_LAUNCH("emit");
        }
        CATGS_CUDA_CHECK(cudaEventRecord(e[kEmit], s));
        // Sort over the used bits only: 32 depth bits plus the tile id's width.
        const std::uint64_t* sorted_keys = m.keys[0].data();
        const std::uint32_t* sorted_values = m.values[0].data();
        if (pass_total > 1) {
            cub::DoubleBuffer<std::uint64_t> kb(m.keys[0].data(), m.keys[1].data());
            cub::DoubleBuffer<std::uint32_t> vb(m.values[0].data(), m.values[1].data());
            std::size_t temp_bytes = 0;
            CATGS_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(nullptr, temp_bytes, kb, vb,
                                                             static_cast<std::int64_t>(pass_total), 0, 32 + tile_bits, s));
            m.sort_temp.reserve(temp_bytes, s);
            CATGS_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(m.sort_temp.data(), temp_bytes, kb, vb,
                                                             static_cast<std::int64_t>(pass_total), 0, 32 + tile_bits, s));
            sorted_keys = kb.Current();
            sorted_values = vb.Current();
        }
        CATGS_CUDA_CHECK(cudaEventRecord(e[kSort], s));
        // Ranges: empty tiles keep [0, 0).
        CATGS_CUDA_CHECK(cudaMemsetAsync(m.range_begin.data(), 0, tiles * sizeof(std::uint64_t), s));
        CATGS_CUDA_CHECK(cudaMemsetAsync(m.range_end.data(), 0, tiles * sizeof(std::uint64_t), s));
        if (pass_total > 0 && !shared_list) {
            ranges_kernel<<<blocks_for(pass_total, kPreprocessThreads), kPreprocessThreads, 0, s>>>(
                pass_total, sorted_keys, static_cast<std::uint32_t>(tiles), m.range_begin.data(), m.range_end.data());
            CATGS_CUDA_CHECK_LAUNCH("ranges");
        }
        CATGS_CUDA_CHECK(cudaEventRecord(e[kRanges], s));
        // Rasterize the band's tile rows.
        const Vec3<T> bg{static_cast<T>(options.background[0]), static_cast<T>(options.background[1]),
                         static_cast<T>(options.background[2])};
        const dim3 grid(static_cast<unsigned>(view.tiles_x), static_cast<unsigned>(rows.end - rows.begin));
        if (grid.x > 0 && grid.y > 0) {
            rasterize_kernel<T><<<grid, dim3(kTileSize, kTileSize), 0, s>>>(
                m.range_begin.data(), m.range_end.data(), shared_list, pass_total, sorted_values, m.projected.data(),
                view, rows.begin, bg, rgb8 ? m.image_rgb8.data() : nullptr, rgb_float ? m.image_float.data() : nullptr);
            CATGS_CUDA_CHECK_LAUNCH("rasterize");
        }
        CATGS_CUDA_CHECK(cudaEventRecord(e[kRasterize], s));
        CATGS_CUDA_CHECK(cudaEventSynchronize(e[kRasterize]));
        float ms = 0;
        CATGS_CUDA_CHECK(cudaEventElapsedTime(&ms, pass_start, e[kEmit]));
        emit_ms += ms;
        CATGS_CUDA_CHECK(cudaEventElapsedTime(&ms, e[kEmit], e[kSort]));
        sort_ms += ms;
        CATGS_CUDA_CHECK(cudaEventElapsedTime(&ms, e[kSort], e[kRanges]));
        ranges_ms += ms;
        CATGS_CUDA_CHECK(cudaEventElapsedTime(&ms, e[kRanges], e[kRasterize]));
        raster_ms += ms;
    }

    // Copy-out through pinned staging buffers.
    CATGS_CUDA_CHECK(cudaEventRecord(e[kRasterize], s));
    if (rgb8) {
        if (m.host_rgb8_bytes < 3 * pixels) {
            cudaFreeHost(m.host_rgb8);
            m.host_rgb8 = nullptr;
            CATGS_CUDA_CHECK(cudaMallocHost(&m.host_rgb8, 3 * pixels));
            m.host_rgb8_bytes = 3 * pixels;
        }
        CATGS_CUDA_CHECK(cudaMemcpyAsync(m.host_rgb8, m.image_rgb8.data(), 3 * pixels, cudaMemcpyDeviceToHost, s));
    }
    if (rgb_float) {
        if (m.host_float_bytes < 3 * pixels * sizeof(float)) {
            cudaFreeHost(m.host_float);
            m.host_float = nullptr;
            CATGS_CUDA_CHECK(cudaMallocHost(&m.host_float, 3 * pixels * sizeof(float)));
            m.host_float_bytes = 3 * pixels * sizeof(float);
        }
        CATGS_CUDA_CHECK(cudaMemcpyAsync(m.host_float, m.image_float.data(), 3 * pixels * sizeof(float),
                                         cudaMemcpyDeviceToHost, s));
    }
    CATGS_CUDA_CHECK(cudaEventRecord(e[kCopy], s));
    CATGS_CUDA_CHECK(cudaEventSynchronize(e[kCopy]));
    if (rgb8) {
        rgb8->width = view.width;
        rgb8->height = view.height;
        rgb8->rgb.assign(m.host_rgb8, m.host_rgb8 + 3 * pixels);
    }
    if (rgb_float) {
        rgb_float->width = view.width;
        rgb_float->height = view.height;
        rgb_float->rgb.assign(m.host_float, m.host_float + 3 * pixels);
    }

    float pre_ms = 0, scan_ms = 0, copy_ms = 0;
    CATGS_CUDA_CHECK(cudaEventElapsedTime(&pre_ms, e[kStart], e[kPreprocess]));
    CATGS_CUDA_CHECK(cudaEventElapsedTime(&copy_ms, e[kRasterize], e[kCopy]));
    CATGS_CUDA_CHECK(cudaEventElapsedTime(&scan_ms, e[kPreprocess], e[kScan]));
    scan_ms += scan_extra_ms;  // the band passes' recounts and scans
    stats.preprocess_ms = pre_ms;
    stats.scan_ms = scan_ms;
    stats.keys_ms = emit_ms;
    stats.sort_ms = sort_ms;
    stats.ranges_ms = ranges_ms;
    stats.rasterize_ms = raster_ms;
    stats.copy_ms = copy_ms;
    stats.total_ms = pre_ms + scan_ms + emit_ms + sort_ms + ranges_ms + raster_ms + copy_ms;
    stats.arena_bytes = m.arena_bytes();
    return stats;
}

template class CudaRenderer<float>;
template class CudaRenderer<double>;

}  // namespace catgs::cuda
