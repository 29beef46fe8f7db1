#include "catgs/scene_ops.hpp"

#include <algorithm>
#include <cmath>
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
    return out;
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
