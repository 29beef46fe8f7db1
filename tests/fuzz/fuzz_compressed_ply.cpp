// libFuzzer target: catgs::read_compressed_ply (SuperSplat's chunked, quantised PLY) on
// arbitrary bytes, with and without drop_invalid (fuzz_scene_reader).

#include <cstddef>
#include <cstdint>

#include "catgs/constants.hpp"
#include "catgs/scene_io.hpp"
#include "scene_checks.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    return catgs::fuzz::fuzz_scene_reader(data, size, catgs::read_compressed_ply, [](const catgs::Scene& scene) {
        catgs::fuzz::require(scene.sh_degree >= 0 && scene.sh_degree <= catgs::kMaxShDegree,
                             "compressed PLY scene with an SH degree outside 0..3");
    });
}
