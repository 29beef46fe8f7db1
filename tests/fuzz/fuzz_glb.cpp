// libFuzzer target: catgs::read_glb (glTF binary with KHR_gaussian_splatting attributes) on
// arbitrary bytes, with and without drop_invalid (fuzz_scene_reader). The seeds are .glb
// files splat-transform 3.7.0 wrote (SH degree 0..3), so mutations reach the GLB container,
// the glTF JSON that tinygltf parses and the accessors read from the BIN chunk.

#include <cstddef>
#include <cstdint>

#include "catgs/scene_io.hpp"
#include "scene_checks.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    return catgs::fuzz::fuzz_scene_reader(data, size, catgs::read_glb, [](const catgs::Scene& scene) {
        catgs::fuzz::require(scene.sh_degree >= 0 && scene.sh_degree <= catgs::kMaxShDegree,
                             "glTF scene with SH degree outside 0..3");
    });
}
