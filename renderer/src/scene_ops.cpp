#include "catgs/scene_ops.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
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

}  // namespace

void partition_into_chunks(Scene& scene) {
    const std::size_t n = scene.count();
    // Cells of a 1024^3 grid over the finite means: 10 bits per axis.
    constexpr int kCellBits = 10;
    constexpr double kCells = static_cast<double>(1u << kCellBits);
    float lo[3], hi[3];
    for (int a = 0; a < 3; ++a) {
        lo[a] = std::numeric_limits<float>::infinity();
        hi[a] = -std::numeric_limits<float>::infinity();
    }
    auto finite_at = [&](std::size_t i) {
        return std::isfinite(scene.positions[3 * i]) && std::isfinite(scene.positions[3 * i + 1]) &&
               std::isfinite(scene.positions[3 * i + 2]);
    };
    for (std::size_t i = 0; i < n; ++i)
        if (finite_at(i))
            for (int a = 0; a < 3; ++a) {
                lo[a] = std::min(lo[a], scene.positions[3 * i + a]);
                hi[a] = std::max(hi[a], scene.positions[3 * i + a]);
            }
    // Key = Morton code << 32 | index: unique keys, so an unstable sort gives the stable order.
    std::vector<std::uint64_t> keys(n);
    for (std::size_t i = 0; i < n; ++i) {
        std::uint64_t code = std::uint64_t{1} << 30;  // past every real code: non-finite last
        if (finite_at(i)) {
            std::uint32_t cell[3];
            for (int a = 0; a < 3; ++a) {
                const double extent = static_cast<double>(hi[a]) - lo[a];
                const double t = extent > 0 ? (scene.positions[3 * i + a] - static_cast<double>(lo[a])) / extent : 0.0;
                cell[a] = static_cast<std::uint32_t>(std::min(kCells - 1, std::max(0.0, t * kCells)));
            }
            code = spread_bits(cell[0]) | spread_bits(cell[1]) << 1 | spread_bits(cell[2]) << 2;
        }
        keys[i] = code << 32 | static_cast<std::uint64_t>(i);
    }
    std::sort(keys.begin(), keys.end());
    std::vector<std::size_t> order(n);
    for (std::size_t j = 0; j < n; ++j) order[j] = static_cast<std::size_t>(keys[j] & 0xffffffffu);
    permute(scene.positions, order, 3);
    permute(scene.scales, order, 3);
    permute(scene.rotations, order, 4);
    permute(scene.opacities, order, 1);
    permute(scene.sh, order, scene.sh_floats_per_gaussian());
    // Chunks follow the octree of the Morton codes, so that none straddles a cell boundary
    // high up the tree (a fixed cut every kChunkGaussians would give a chunk that spans half
    // the scene wherever the curve jumps between octants): a cell with more Gaussians than a
    // chunk holds is split into its 8 children; consecutive children are grouped while they
    // fit one chunk (their union stays inside the parent cell).
    scene.chunks.clear();
    auto code_of = [&](std::size_t j) { return keys[j] >> 32; };
    auto emit = [&](std::size_t begin, std::size_t end) {
        for (std::size_t b = begin; b < end; b += kChunkGaussians) {
            Chunk c;
            c.begin = static_cast<std::uint32_t>(b);
            c.end = static_cast<std::uint32_t>(std::min<std::size_t>(end, b + kChunkGaussians));
            scene.chunks.push_back(c);
        }
    };
    auto split = [&](auto& self, std::size_t begin, std::size_t end, int level) -> void {
        if (end - begin <= kChunkGaussians || level == kCellBits) {
            emit(begin, end);  // the deepest cells (or the non-finite tail) are cut in order
            return;
        }
        const int shift = 3 * (kCellBits - 1 - level);
        std::size_t group_begin = begin, child_begin = begin;
        while (child_begin < end) {
            const std::uint64_t child = code_of(child_begin) >> shift;
            std::size_t child_end = child_begin;
            while (child_end < end && code_of(child_end) >> shift == child) ++child_end;
            if (child_end - child_begin > kChunkGaussians) {
                if (group_begin < child_begin) emit(group_begin, child_begin);
                self(self, child_begin, child_end, level + 1);
                group_begin = child_end;
            } else if (child_end - group_begin > kChunkGaussians) {
                emit(group_begin, child_begin);
                group_begin = child_begin;
            }
            child_begin = child_end;
        }
        if (group_begin < end) emit(group_begin, end);
    };
    // The non-finite tail (code 2^30) is its own run after the finite codes.
    std::size_t finite_end = n;
    while (finite_end > 0 && code_of(finite_end - 1) >> 30) --finite_end;
    split(split, 0, finite_end, 0);
    emit(finite_end, n);
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
