// Invariants of a scene returned by a reader (scene.hpp, scene_io.hpp), checked by the
// reader fuzz targets on every input that loads.
#pragma once

#include <cmath>
#include <cstdint>
#include <string>

#include "catgs/constants.hpp"
#include "catgs/error.hpp"
#include "catgs/scene.hpp"
#include "catgs/scene_io.hpp"
#include "fuzz_util.hpp"

namespace catgs::fuzz {

inline void check_scene(const Scene& scene, const LoadReport& report, const LoadOptions& options) {
    try {
        scene.check_consistent("fuzzed scene");
    } catch (const Error& e) {
        violation(e.what());
    }
    const std::size_t n = scene.count();
    require(n > 0, "a scene loaded without Gaussians");
    require(report.records <= options.max_records, "more records than max_records");
    require(n + report.dropped_invalid + report.dropped_transparent == report.records, "kept + dropped != records");
    require(options.drop_invalid || report.dropped_invalid == 0, "records dropped without drop_invalid");
    for (int a = 0; a < 3; ++a) {
        require(std::isfinite(scene.origin[a]), "non-finite origin");
        require(std::isfinite(scene.bounds.min[a]) && std::isfinite(scene.bounds.max[a]) &&
                    scene.bounds.min[a] <= scene.bounds.max[a],
                "bounds not finite or min > max");
    }
    for (std::size_t i = 0; i < n; ++i) {
        for (int a = 0; a < 3; ++a) {
            require(std::isfinite(scene.positions[3 * i + a]),
                    [&] { return "non-finite position " + std::to_string(i); });
            require(std::isfinite(scene.scales[3 * i + a]), [&] { return "non-finite scale " + std::to_string(i); });
        }
        double norm2 = 0;
        for (int c = 0; c < 4; ++c) {
            const double q = scene.rotations[4 * i + c];
            require(std::isfinite(q), [&] { return "non-finite rotation " + std::to_string(i); });
            norm2 += q * q;
        }
        require(std::fabs(norm2 - 1.0) < 1e-5,
                [&] { return "rotation " + std::to_string(i) + " is not a unit quaternion"; });
        const double opacity = scene.opacities[i];
        require(opacity >= kMinAlpha && opacity <= 1.0,
                [&] { return "opacity " + std::to_string(i) + " outside [1/255, 1]"; });
    }
    for (float v : scene.sh) require(std::isfinite(v), "non-finite SH coefficient");
}

/// The body of a scene reader's target: writes the input to a file and reads it twice with
/// `read` (read_ply, read_splat): with the defaults (invalid records are errors) and with
/// drop_invalid and without recentring, so both paths of SceneBuilder are searched. A loaded
/// scene must pass check_scene and `extra`; an error must be a one-line catgs::Error naming
/// the file.
template <typename Read, typename Extra>
int fuzz_scene_reader(const std::uint8_t* data, std::size_t size, Read read, Extra extra) {
    if (size > kMaxInputBytes) return -1;
    static MemoryFile file;
    const std::string& path = file.write(data, size);
    for (bool drop_invalid : {false, true}) {
        LoadOptions options;
        options.drop_invalid = drop_invalid;
        options.recentre = !drop_invalid;
        options.max_records = kMaxRecords;
        LoadReport report;
        try {
            const Scene scene = read(path, options, &report);
            check_scene(scene, report, options);
            extra(scene);
        } catch (const Error& e) {
            check_file_message(e.what(), path);
        }
    }
    return 0;
}

}  // namespace catgs::fuzz
