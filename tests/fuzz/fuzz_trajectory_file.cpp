// libFuzzer target: catgs::read_trajectory (our "timestamp px py pz qw qx qy qz [fx fy cx cy
// width height]" text format) on arbitrary bytes, with valid default intrinsics.

#include <cstddef>
#include <cstdint>

#include "camera_checks.hpp"
#include "catgs/camera.hpp"
#include "catgs/error.hpp"
#include "catgs/trajectory.hpp"
#include "fuzz_util.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    if (size > catgs::fuzz::kMaxInputBytes) return -1;
    static catgs::fuzz::MemoryFile file;
    static const catgs::Intrinsics defaults = catgs::intrinsics_from_fov(64, 48, 70.0);
    const std::string& path = file.write(data, size);
    try {
        catgs::fuzz::check_cameras(catgs::read_trajectory(path, defaults), "trajectory");
    } catch (const catgs::Error& e) {
        catgs::fuzz::check_file_message(e.what(), path);
    }
    return 0;
}
