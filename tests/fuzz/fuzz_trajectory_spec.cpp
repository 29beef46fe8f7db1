// libFuzzer target: procedural UAV flights, catgs::make_trajectory("builtin:KIND?key=value&...")
// over the bounds of four scenes (a city block, a small object, a UTM-placed capture, and the
// largest bounds the scene readers accept, +-1e30 m).
//
// Allocation and time cap: only specs with an explicit frames=N, N <= kMaxFrames, reach the
// generator (the parser allows 10^6 frames, ~200 MB of cameras and seconds per input; the
// default is 300). Longer flights take the same code paths: speed and fps reach any part of
// a pattern within a few frames.

#include <cstddef>
#include <cstdint>
#include <string>

#include "camera_checks.hpp"
#include "catgs/builtin_spec.hpp"
#include "catgs/camera.hpp"
#include "catgs/error.hpp"
#include "catgs/scene.hpp"
#include "catgs/trajectory.hpp"
#include "fuzz_util.hpp"

namespace {

constexpr std::uint64_t kMaxFrames = 32;

/// False for specs that would generate more than kMaxFrames cameras (or the default 300).
bool few_frames(const std::string& spec) {
    try {
        for (const auto& [key, value] :
             catgs::detail::builtin_params(spec, {"speed", "fps", "altitude", "pitch", "frames", "up", "seed"}))
            if (key == "frames") return catgs::detail::spec_integer(spec, key, value) <= kMaxFrames;
    } catch (const catgs::Error&) {
        return true;  // make_trajectory refuses it before generating anything
    }
    return false;
}

catgs::Bounds box(double x0, double y0, double z0, double x1, double y1, double z1) {
    catgs::Bounds b;
    b.min = {x0, y0, z0};
    b.max = {x1, y1, z1};
    return b;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    if (size > 4096) return -1;
    const std::string spec = catgs::fuzz::as_string(data, size);
    if (!few_frames(spec)) return -1;
    static const catgs::Bounds kBounds[] = {
        box(-200, -150, 0, 200, 150, 60),
        box(-1, -1, -1, 1, 1, 1),
        box(500000, 4000000, 100, 500300, 4000200, 150),
        box(-1e30, -1e30, -1e30, 1e30, 1e30, 1e30),
    };
    static const catgs::Intrinsics intrinsics = catgs::intrinsics_from_fov(64, 48, 70.0);
    for (const catgs::Bounds& bounds : kBounds) {
        try {
            const auto cameras = catgs::make_trajectory(spec, bounds, intrinsics);
            catgs::fuzz::require(cameras.size() <= kMaxFrames, "more frames than asked for");
            catgs::fuzz::check_cameras(cameras, "flight");
        } catch (const catgs::Error&) {
            // Spec errors quote the spec as given (a NUL in it cuts what() short): any message.
        }
    }
    return 0;
}
