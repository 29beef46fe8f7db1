#include "catgs/scene_ops.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>
#include <string>
#include <vector>

#include "catgs/error.hpp"

namespace catgs {

Bounds percentile_bounds(const Scene& scene, double low, double high) {
    Bounds b;
    const std::size_t n = scene.count();
    if (n == 0) return b;
    std::vector<float> values(n);
    for (int a = 0; a < 3; ++a) {
        for (std::size_t i = 0; i < n; ++i) values[i] = scene.positions[3 * i + a];
        const auto lo = static_cast<std::size_t>(low * static_cast<double>(n - 1));
        const auto hi = static_cast<std::size_t>(high * static_cast<double>(n - 1));
        std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(lo), values.end());
        b.min[a] = scene.origin[a] + values[lo];
        std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(hi), values.end());
        b.max[a] = scene.origin[a] + values[hi];
    }
    return b;
}

void truncate_sh(Scene& scene, int degree) {
    if (degree < 0) throw Error("SH degree " + std::to_string(degree) + ": expected 0..3");
    if (degree >= scene.sh_degree) return;
    const std::size_t old_stride = scene.sh_floats_per_gaussian();
    const std::size_t new_stride = 3u * static_cast<std::size_t>(sh_coefficient_count(degree));
    // In place, front to back: Gaussian i's new block never overlaps a later one's old block.
    for (std::size_t i = 0; i < scene.count(); ++i)
        std::copy_n(scene.sh.begin() + static_cast<std::ptrdiff_t>(i * old_stride), new_stride,
                    scene.sh.begin() + static_cast<std::ptrdiff_t>(i * new_stride));
    scene.sh.resize(scene.count() * new_stride);
    scene.sh.shrink_to_fit();
    scene.sh_degree = degree;
}

Scene replicate_grid(const Scene& scene, int nx, int ny, int up_axis) {
    if (nx < 1 || ny < 1)
        throw Error("grid " + std::to_string(nx) + "x" + std::to_string(ny) + ": both counts must be at least 1");
    if (up_axis < 0 || up_axis > 2) throw Error("grid: up axis must be 0, 1 or 2");
    const int ax = up_axis == 0 ? 1 : 0, ay = up_axis == 2 ? 1 : 2;
    const Bounds cell = percentile_bounds(scene, 0.01, 0.99);
    const double ex = cell.max[ax] - cell.min[ax], ey = cell.max[ay] - cell.min[ay];
    // Positions relative to the origin, cell limits likewise.
    const double lo_x = cell.min[ax] - scene.origin[ax], hi_x = cell.max[ax] - scene.origin[ax];
    const double lo_y = cell.min[ay] - scene.origin[ay], hi_y = cell.max[ay] - scene.origin[ay];
    std::vector<std::size_t> kept;
    for (std::size_t i = 0; i < scene.count(); ++i) {
        const double x = scene.positions[3 * i + ax], y = scene.positions[3 * i + ay];
        if (x >= lo_x && x <= hi_x && y >= lo_y && y <= hi_y) kept.push_back(i);
    }
    Scene out;
    out.sh_degree = scene.sh_degree;
    out.origin = scene.origin;
    out.resize(kept.size() * static_cast<std::size_t>(nx) * static_cast<std::size_t>(ny));
    const std::size_t stride = scene.sh_floats_per_gaussian();
    std::size_t o = 0;
    for (int gy = 0; gy < ny; ++gy)
        for (int gx = 0; gx < nx; ++gx) {
            // Centre the grid on the original cell.
            const double dx = (gx - 0.5 * (nx - 1)) * ex, dy = (gy - 0.5 * (ny - 1)) * ey;
            for (std::size_t i : kept) {
                for (int a = 0; a < 3; ++a) out.positions[3 * o + a] = scene.positions[3 * i + a];
                out.positions[3 * o + ax] = static_cast<float>(scene.positions[3 * i + ax] + dx);
                out.positions[3 * o + ay] = static_cast<float>(scene.positions[3 * i + ay] + dy);
                std::copy_n(&scene.scales[3 * i], 3, &out.scales[3 * o]);
                std::copy_n(&scene.rotations[4 * i], 4, &out.rotations[4 * o]);
                out.opacities[o] = scene.opacities[i];
                std::copy_n(&scene.sh[stride * i], stride, &out.sh[stride * o]);
                ++o;
            }
        }
    out.update_bounds();
    if (!scene.chunks.empty()) partition_into_chunks(out);
    return out;
}

namespace {

// Spreads the low 10 bits of v to every third bit (the x, y or z lane of a 30-bit Morton code).
std::uint32_t spread_bits(std::uint32_t v) {
    v &= 0x3ffu;
    v = (v | (v << 16)) & 0x030000ffu;
    v = (v | (v << 8)) & 0x0300f00fu;
    v = (v | (v << 4)) & 0x030c30c3u;
    v = (v | (v << 2)) & 0x09249249u;
    return v;
}

template <typename V>
void permute(V& values, const std::vector<std::size_t>& order, std::size_t stride) {
    V out(values.size());
    for (std::size_t j = 0; j < order.size(); ++j) std::copy_n(&values[stride * order[j]], stride, &out[stride * j]);
    values.swap(out);
}

// Cells of a 1024^3 grid over a box: 10 bits per axis, a 30-bit code.
constexpr int kCellBits = 10;

// A deepest cell that still holds more than a chunk is cut again over its own box at most this
// many times (each time 10 more bits an axis); beyond that the Gaussians lie within float's
// spacing of each other and are cut in order.
constexpr int kMaxRefinements = 6;

struct MortonBox {
    float lo[3], hi[3];
};

bool finite_position(const Scene& scene, std::size_t i) {
    return std::isfinite(scene.positions[3 * i]) && std::isfinite(scene.positions[3 * i + 1]) &&
           std::isfinite(scene.positions[3 * i + 2]);
}

/// The Gaussian a key indexes (its low 32 bits).
std::size_t index_of(std::uint64_t key) {
    return static_cast<std::size_t>(key & 0xffffffffu);
}

/// The box of the positions (finite) of the Gaussians keys[begin, end) index.
MortonBox box_of(const Scene& scene, const std::vector<std::uint64_t>& keys, std::size_t begin, std::size_t end) {
    MortonBox b;
    for (int a = 0; a < 3; ++a) {
        b.lo[a] = std::numeric_limits<float>::infinity();
        b.hi[a] = -std::numeric_limits<float>::infinity();
    }
    for (std::size_t j = begin; j < end; ++j) {
        const std::size_t i = index_of(keys[j]);
        for (int a = 0; a < 3; ++a) {
            b.lo[a] = std::min(b.lo[a], scene.positions[3 * i + a]);
            b.hi[a] = std::max(b.hi[a], scene.positions[3 * i + a]);
        }
    }
    return b;
}

/// Key = Morton code in `box` << 32 | index, for a finite position: unique keys, so an unstable
/// sort gives the stable order.
std::uint64_t morton_key(const Scene& scene, std::size_t i, const MortonBox& box) {
    constexpr double kCells = static_cast<double>(1u << kCellBits);
    std::uint32_t cell[3];
    for (int a = 0; a < 3; ++a) {
        const double extent = static_cast<double>(box.hi[a]) - box.lo[a];
        const double t = extent > 0 ? (scene.positions[3 * i + a] - static_cast<double>(box.lo[a])) / extent : 0.0;
        cell[a] = static_cast<std::uint32_t>(std::min(kCells - 1, std::max(0.0, t * kCells)));
    }
    const std::uint64_t code = spread_bits(cell[0]) | spread_bits(cell[1]) << 1 | spread_bits(cell[2]) << 2;
    return code << 32 | static_cast<std::uint64_t>(i);
}

/// Orders keys[begin, end) (finite positions only) along the octree of their own box and
/// appends chunks that follow it: a cell with more Gaussians than a chunk holds is split into
/// its 8 children, and consecutive children are grouped while they fit one chunk (their union
/// stays inside the parent cell), so no chunk straddles a cell boundary high up the tree (a
/// fixed cut every kChunkGaussians would give a chunk that spans half the scene wherever the
/// curve jumps between octants).
class OctreeChunker {
public:
    OctreeChunker(const Scene& scene, std::vector<std::uint64_t>& keys, std::vector<Chunk>& chunks)
        : scene_(scene), keys_(keys), chunks_(chunks) {}

    void order_and_cut(std::size_t begin, std::size_t end, int refinement) {
        const MortonBox box = box_of(scene_, keys_, begin, end);
        for (std::size_t j = begin; j < end; ++j) keys_[j] = morton_key(scene_, index_of(keys_[j]), box);
        std::sort(keys_.begin() + static_cast<std::ptrdiff_t>(begin), keys_.begin() + static_cast<std::ptrdiff_t>(end));
        split(begin, end, 0, refinement);
    }

    void emit(std::size_t begin, std::size_t end) {
        for (std::size_t b = begin; b < end; b += kChunkGaussians) {
            Chunk c;
            c.begin = static_cast<std::uint32_t>(b);
            c.end = static_cast<std::uint32_t>(std::min<std::size_t>(end, b + kChunkGaussians));
            chunks_.push_back(c);
        }
    }

private:
    std::uint64_t code_of(std::size_t j) const { return keys_[j] >> 32; }

    void split(std::size_t begin, std::size_t end, int level, int refinement) {
        if (end - begin <= kChunkGaussians) return emit(begin, end);
        if (level == kCellBits) {
            // A deepest cell too full for one chunk: the bulk of a scene whose box a few far
            // strays stretch (a stray 10^4 extents out leaves the whole bulk in one cell) is
            // ordered again over its own box, so chunks stay compact however far strays lie.
            if (refinement < kMaxRefinements) return order_and_cut(begin, end, refinement + 1);
            return emit(begin, end);
        }
        const int shift = 3 * (kCellBits - 1 - level);
        std::size_t group_begin = begin, child_begin = begin;
        while (child_begin < end) {
            const std::uint64_t child = code_of(child_begin) >> shift;
            std::size_t child_end = child_begin;
            while (child_end < end && code_of(child_end) >> shift == child) ++child_end;
            if (child_end - child_begin > kChunkGaussians) {
                if (group_begin < child_begin) emit(group_begin, child_begin);
                split(child_begin, child_end, level + 1, refinement);
                group_begin = child_end;
            } else if (child_end - group_begin > kChunkGaussians) {
                emit(group_begin, child_begin);
                group_begin = child_begin;
            }
            child_begin = child_end;
        }
        if (group_begin < end) emit(group_begin, end);
    }

    const Scene& scene_;
    std::vector<std::uint64_t>& keys_;
    std::vector<Chunk>& chunks_;
};

}  // namespace

void partition_into_chunks(Scene& scene) {
    const std::size_t n = scene.count();
    // The finite positions first; the non-finite ones go last, in file order, in chunks of
    // their own (never culled).
    std::vector<std::uint64_t> keys(n);
    std::iota(keys.begin(), keys.end(), std::uint64_t{0});
    const std::size_t finite_end = static_cast<std::size_t>(
        std::stable_partition(keys.begin(), keys.end(), [&](std::uint64_t i) { return finite_position(scene, i); }) -
        keys.begin());
    scene.chunks.clear();
    OctreeChunker chunker(scene, keys, scene.chunks);
    chunker.order_and_cut(0, finite_end, 0);
    chunker.emit(finite_end, n);
    std::vector<std::size_t> order(n);
    for (std::size_t j = 0; j < n; ++j) order[j] = index_of(keys[j]);
    permute(scene.positions, order, 3);
    permute(scene.scales, order, 3);
    permute(scene.rotations, order, 4);
    permute(scene.opacities, order, 1);
    permute(scene.sh, order, scene.sh_floats_per_gaussian());
    scene.update_chunk_bounds();
}

std::pair<int, int> parse_grid(const std::string& text) {
    const auto x = text.find('x');
    auto bad = [&]() { return Error("--grid '" + text + "': expected NxM with positive integers, e.g. 3x3"); };
    if (x == std::string::npos) throw bad();
    try {
        std::size_t used_a = 0, used_b = 0;
        const int a = std::stoi(text.substr(0, x), &used_a), b = std::stoi(text.substr(x + 1), &used_b);
        if (used_a != x || used_b != text.size() - x - 1 || a < 1 || b < 1 || a > 64 || b > 64) throw bad();
        return {a, b};
    } catch (const std::logic_error&) {
        throw bad();
    }
}

int parse_up_axis(const std::string& text) {
    std::string t = text;
    if (!t.empty() && (t[0] == '-' || t[0] == '+')) t = t.substr(1);
    if (t == "x") return 0;
    if (t == "y") return 1;
    if (t == "z") return 2;
    throw Error("up axis '" + text + "': expected x, y, z, -x, -y or -z");
}

}  // namespace catgs
