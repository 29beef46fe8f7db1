// libFuzzer target: catgs::read_splat (32-byte antimatter15 records) on arbitrary bytes, with
// and without drop_invalid (fuzz_scene_reader).

#include <cstddef>
#include <cstdint>

#include "catgs/scene_io.hpp"
#include "scene_checks.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    return catgs::fuzz::fuzz_scene_reader(data, size, catgs::read_splat, [](const catgs::Scene& scene) {
        catgs::fuzz::require(scene.sh_degree == 0, ".splat scene with SH degree > 0");
    });
}
