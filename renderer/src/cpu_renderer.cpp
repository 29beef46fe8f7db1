#include "catgs/cpu_renderer.hpp"

#include <chrono>

#include "catgs/error.hpp"
#include "catgs/parallel.hpp"
#include "catgs/stages/blend.hpp"
#include "catgs/stages/tiles.hpp"
#include "catgs/stages/view.hpp"

namespace catgs {
namespace {

// Chunk sizes for parallel_for: large enough that scheduling costs nothing, small enough to
// balance two to sixteen threads on scenes of 10^4 Gaussians and up.
constexpr std::size_t kGaussianGrain = 4096;
constexpr std::size_t kTileGrain = 4;

// Radix sort digit width: 8 bits keeps the histogram (256 counters) in L1.
constexpr int kRadixBits = 8;

using Clock = std::chrono::steady_clock;
double elapsed_ms(Clock::time_point since) {
    return std::chrono::duration<double, std::milli>(Clock::now() - since).count();
}

int bit_width(std::uint64_t v) {
    int bits = 0;
    while (v) {
        ++bits;
        v >>= 1;
    }
    return bits;
}

}  // namespace

template <typename T>
CpuRenderer<T>::CpuRenderer(int threads) : threads_(threads > 0 ? threads : default_thread_count()) {}

template <typename T>
FrameStats CpuRenderer<T>::render(const Scene& scene, const Camera& camera, const RenderOptions& options, ImageF& out) {
    validate(camera.intrinsics, "camera '" + camera.name + "'");
    const View<T> view = make_view<T>(camera, scene.origin, options.near_plane);
    FrameStats stats;
    const auto start = Clock::now();
    auto t = Clock::now();
    preprocess(scene, view, options.culling);
    stats.preprocess_ms = elapsed_ms(t);
    t = Clock::now();
    emit_keys(view, options.culling);
    stats.keys_ms = elapsed_ms(t);
    t = Clock::now();
    sort_pairs(view);
    stats.sort_ms = elapsed_ms(t);
    t = Clock::now();
    find_tile_ranges(view, options.culling);
    stats.ranges_ms = elapsed_ms(t);
    t = Clock::now();
    rasterize(view, options, out);
    stats.rasterize_ms = elapsed_ms(t);
    stats.total_ms = elapsed_ms(start);
    stats.pairs = keys_.size();
    for (std::uint32_t n : tiles_touched_) stats.visible += n > 0;
    return stats;
}

// Stage 1: project every Gaussian and count the tiles it touches (0 = culled).
template <typename T>
void CpuRenderer<T>::preprocess(const Scene& scene, const View<T>& view, Culling culling) {
    const std::size_t n = scene.count();
    projected_.resize(n);
    tiles_touched_.assign(n, 0);
    const std::size_t sh_stride = scene.sh_floats_per_gaussian();
    parallel_for(n, kGaussianGrain, threads_, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i) {
            const GaussianRef g{&scene.positions[3 * i], &scene.scales[3 * i], &scene.rotations[4 * i],
                                scene.opacities[i], &scene.sh[sh_stride * i], scene.sh_degree};
            if (!project_gaussian(g, view, projected_[i])) continue;
            tiles_touched_[i] = for_each_touched_tile(projected_[i], culling, view, [](std::uint32_t) {});
        }
    });
}

// Stage 2: exclusive scan of the tile counts (64-bit), then emit (tile | depth) keys in
// Gaussian order through the same predicate the count used.
template <typename T>
void CpuRenderer<T>::emit_keys(const View<T>& view, Culling culling) {
    const std::size_t n = tiles_touched_.size();
    offsets_.resize(n);
    std::uint64_t total = 0;
    for (std::size_t i = 0; i < n; ++i) {
        offsets_[i] = total;
        total += tiles_touched_[i];
    }
    keys_.resize(total);
    values_.resize(total);
    parallel_for(n, kGaussianGrain, threads_, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i) {
            if (tiles_touched_[i] == 0) continue;
            std::uint64_t slot = offsets_[i];
            const float depth = static_cast<float>(projected_[i].depth);
            for_each_touched_tile(projected_[i], culling, view, [&](std::uint32_t tile) {
                keys_[slot] = make_sort_key(tile, depth);
                values_[slot] = static_cast<std::uint32_t>(i);
                ++slot;
            });
        }
    });
}

// Stage 3: stable LSD radix sort over the used key bits only (depth: 32, tile: bit width of
// the largest tile id), as CUB does on the GPU. Stability keeps Gaussian order for ties.
template <typename T>
void CpuRenderer<T>::sort_pairs(const View<T>& view) {
    const std::size_t n = keys_.size();
    const int tile_bits = bit_width(static_cast<std::uint64_t>(view.tiles_x) * view.tiles_y);
    const int passes = (32 + tile_bits + kRadixBits - 1) / kRadixBits;
    sort_keys_tmp_.resize(n);
    sort_values_tmp_.resize(n);
    constexpr std::size_t kBuckets = std::size_t{1} << kRadixBits;
    for (int pass = 0; pass < passes; ++pass) {
        const int shift = pass * kRadixBits;
        std::uint64_t count[kBuckets] = {};
        for (std::size_t i = 0; i < n; ++i) ++count[(keys_[i] >> shift) & (kBuckets - 1)];
        std::uint64_t sum = 0;
        for (auto& c : count) {
            std::uint64_t here = c;
            c = sum;
            sum += here;
        }
        for (std::size_t i = 0; i < n; ++i) {
            const std::uint64_t slot = count[(keys_[i] >> shift) & (kBuckets - 1)]++;
            sort_keys_tmp_[slot] = keys_[i];
            sort_values_tmp_[slot] = values_[i];
        }
        keys_.swap(sort_keys_tmp_);
        values_.swap(sort_values_tmp_);
    }
}

// Stage 4: [begin, end) of every tile in the sorted pairs. Exact mode has one list, which
// every tile shares.
template <typename T>
void CpuRenderer<T>::find_tile_ranges(const View<T>& view, Culling culling) {
    const std::size_t tiles = static_cast<std::size_t>(view.tiles_x) * view.tiles_y;
    ranges_.assign(tiles, TileRange{});
    const std::size_t n = keys_.size();
    if (culling == Culling::exact) {
        for (auto& r : ranges_) r = {0, n};
        return;
    }
    for (std::size_t i = 0; i < n; ++i) {
        const std::uint32_t tile = key_tile(keys_[i]);
        if (i == 0 || key_tile(keys_[i - 1]) != tile) ranges_[tile].begin = i;
        if (i + 1 == n || key_tile(keys_[i + 1]) != tile) ranges_[tile].end = i + 1;
    }
}

// Stage 5: one tile at a time, each pixel blends its tile's list front to back.
template <typename T>
void CpuRenderer<T>::rasterize(const View<T>& view, const RenderOptions& options, ImageF& out) {
    out.resize(view.width, view.height);
    const Vec3<T> background{static_cast<T>(options.background[0]), static_cast<T>(options.background[1]),
                             static_cast<T>(options.background[2])};
    const std::size_t tiles = ranges_.size();
    parallel_for(tiles, kTileGrain, threads_, [&](std::size_t begin, std::size_t end) {
        std::vector<const Projected<T>*> list;
        for (std::size_t tile = begin; tile < end; ++tile) {
            const TileRange range = ranges_[tile];
            list.clear();
            for (std::uint64_t j = range.begin; j < range.end; ++j) list.push_back(&projected_[values_[j]]);
            const int x0 = static_cast<int>(tile % view.tiles_x) * kTileSize;
            const int y0 = static_cast<int>(tile / view.tiles_x) * kTileSize;
            const int x1 = std::min(x0 + kTileSize, view.width), y1 = std::min(y0 + kTileSize, view.height);
            for (int y = y0; y < y1; ++y)
                for (int x = x0; x < x1; ++x) {
                    PixelAccumulator<T> acc;
                    const T px = static_cast<T>(x) + T(0.5), py = static_cast<T>(y) + T(0.5);
                    for (const Projected<T>* g : list)
                        if (blend_gaussian(acc, g->mean, g->conic, g->opacity, g->colour, px, py)) break;
                    const Vec3<T> c = finish_pixel(acc, background);
                    float* dst = &out.rgb[3 * (static_cast<std::size_t>(y) * view.width + x)];
                    dst[0] = static_cast<float>(c.x);
                    dst[1] = static_cast<float>(c.y);
                    dst[2] = static_cast<float>(c.z);
                }
        }
    });
}

template class CpuRenderer<float>;
template class CpuRenderer<double>;

Culling parse_culling(const std::string& name) {
    if (name == "exact") return Culling::exact;
    if (name == "bbox3sigma") return Culling::bbox3sigma;
    if (name == "opacity-aware") return Culling::opacity_aware;
    throw Error("unknown culling mode '" + name + "' (expected exact, bbox3sigma or opacity-aware)");
}

const char* culling_name(Culling culling) {
    switch (culling) {
        case Culling::exact: return "exact";
        case Culling::bbox3sigma: return "bbox3sigma";
        case Culling::opacity_aware: return "opacity-aware";
    }
    return "?";
}

}  // namespace catgs
