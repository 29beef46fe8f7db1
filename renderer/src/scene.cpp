#include "catgs/scene.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <vector>

#include <nlohmann/json.hpp>

#include "catgs/error.hpp"

namespace catgs {

std::size_t Scene::bytes() const {
    return sizeof(float) * (positions.size() + scales.size() + rotations.size() + opacities.size() + sh.size());
}

void Scene::resize(std::size_t n) {
    chunks.clear();
    positions.resize(3 * n);
    scales.resize(3 * n);
    rotations.resize(4 * n);
    opacities.resize(n);
    sh.resize(sh_floats_per_gaussian() * n);
}

void Scene::update_bounds() {
    if (count() == 0) {
        bounds = Bounds{};
        return;
    }
    Bounds b;
    for (int a = 0; a < 3; ++a) {
        b.min[a] = std::numeric_limits<double>::infinity();
        b.max[a] = -std::numeric_limits<double>::infinity();
    }
    for (std::size_t i = 0; i < count(); ++i)
        for (int a = 0; a < 3; ++a) {
            double v = origin[a] + static_cast<double>(positions[3 * i + a]);
            b.min[a] = std::min(b.min[a], v);
            b.max[a] = std::max(b.max[a], v);
        }
    bounds = b;
}

std::array<double, 3> scene_origin(const Bounds& bounds, std::size_t n,
                                   const std::function<double(std::size_t, int)>& world) {
    std::array<double, 3> origin{0, 0, 0};
    if (n == 0) return origin;
    const std::size_t stride = (n + kOriginSample - 1) / kOriginSample;
    std::vector<double> sample;
    sample.reserve(n / stride + 1);
    for (int a = 0; a < 3; ++a) {
        origin[a] = 0.5 * (bounds.min[a] + bounds.max[a]);
        sample.clear();
        for (std::size_t i = 0; i < n; i += stride) {
            const double v = world(i, a);
            if (std::isfinite(v)) sample.push_back(v);
        }
        if (sample.empty()) continue;
        const auto at = [&](double share) {
            const auto k = static_cast<std::ptrdiff_t>(share * static_cast<double>(sample.size() - 1));
            std::nth_element(sample.begin(), sample.begin() + k, sample.end());
            return sample[static_cast<std::size_t>(k)];
        };
        const double lo = at(kOriginStrayShare), hi = at(1.0 - kOriginStrayShare);
        const double bulk_centre = 0.5 * (lo + hi), bulk_half = 0.5 * (hi - lo);
        if (std::abs(origin[a] - bulk_centre) > kOriginStrayFactor * bulk_half) origin[a] = bulk_centre;
    }
    return origin;
}

void Scene::recentre() {
    update_bounds();
    const std::array<double, 3> centre = scene_origin(bounds, count(), [this](std::size_t i, int a) {
        return origin[a] + static_cast<double>(positions[3 * i + a]);
    });
    for (std::size_t i = 0; i < count(); ++i)
        for (int a = 0; a < 3; ++a)
            positions[3 * i + a] =
                static_cast<float>((origin[a] + static_cast<double>(positions[3 * i + a])) - centre[a]);
    origin = centre;
    update_bounds();
    update_chunk_bounds();
}

void Scene::update_chunk_bounds() {
    constexpr float kInf = std::numeric_limits<float>::infinity();
    for (Chunk& c : chunks) {
        float lo[3] = {kInf, kInf, kInf}, hi[3] = {-kInf, -kInf, -kInf}, largest = 0.0f;
        bool finite = true;
        for (std::size_t i = c.begin; i < c.end; ++i) {
            for (int a = 0; a < 3; ++a) {
                const float p = positions[3 * i + a], s = std::fabs(scales[3 * i + a]);
                finite = finite && std::isfinite(p) && std::isfinite(s);
                lo[a] = std::min(lo[a], p);
                hi[a] = std::max(hi[a], p);
                largest = std::max(largest, s);
            }
        }
        for (int a = 0; a < 3; ++a) {
            c.lo[a] = finite ? lo[a] : -kInf;
            c.hi[a] = finite ? hi[a] : kInf;
        }
        c.radius = finite ? static_cast<float>(kChunkSigmas * largest) : kInf;
    }
}

void Scene::check_consistent(const std::string& what) const {
    const std::size_t n = count();
    if (sh_degree < 0 || sh_degree > kMaxShDegree)
        throw Error(what + ": SH degree " + std::to_string(sh_degree) + " is outside 0..3");
    auto expect = [&](const char* name, std::size_t got, std::size_t want) {
        if (got != want)
            throw Error(what + ": array '" + name + "' holds " + std::to_string(got) + " floats, expected " +
                        std::to_string(want));
    };
    expect("positions", positions.size(), 3 * n);
    expect("scales", scales.size(), 3 * n);
    expect("rotations", rotations.size(), 4 * n);
    expect("sh", sh.size(), sh_floats_per_gaussian() * n);
    std::size_t next = 0;
    for (std::size_t c = 0; c < chunks.size(); ++c) {
        const Chunk& k = chunks[c];
        if (k.begin != next || k.end <= k.begin || k.end - k.begin > kChunkGaussians || k.end > n)
            throw Error(what + ": chunk " + std::to_string(c) + " covers [" + std::to_string(k.begin) + ", " +
                        std::to_string(k.end) + "), expected to start at " + std::to_string(next) + " with 1.." +
                        std::to_string(kChunkGaussians) + " of the " + std::to_string(n) + " Gaussians");
        next = k.end;
    }
    if (!chunks.empty() && next != n)
        throw Error(what + ": chunks cover " + std::to_string(next) + " of the " + std::to_string(n) + " Gaussians");
}

std::string describe(const Scene& s) {
    std::ostringstream o;
    o.precision(10);
    o << "gaussians " << s.count() << ", SH degree " << s.sh_degree << ", bounds [" << s.bounds.min[0] << ", "
      << s.bounds.min[1] << ", " << s.bounds.min[2] << "] .. [" << s.bounds.max[0] << ", " << s.bounds.max[1] << ", "
      << s.bounds.max[2] << "], origin [" << s.origin[0] << ", " << s.origin[1] << ", " << s.origin[2] << "], memory "
      << s.bytes() << " bytes (" << std::fixed;
    o.precision(1);
    o << static_cast<double>(s.bytes()) / (1024.0 * 1024.0) << " MiB)";
    return o.str();
}

std::string describe_json(const Scene& s) {
    nlohmann::json j;
    j["gaussians"] = s.count();
    j["sh_degree"] = s.sh_degree;
    j["bounds"] = {{"min", s.bounds.min}, {"max", s.bounds.max}};
    j["origin"] = s.origin;
    j["bytes"] = s.bytes();
    return j.dump();
}

}  // namespace catgs
