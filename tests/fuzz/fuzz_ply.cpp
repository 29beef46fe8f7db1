// libFuzzer target: catgs::read_ply (graphdeco PLY, binary LE/BE and ASCII) on arbitrary bytes,
// with and without drop_invalid (fuzz_scene_reader).

#include <cstddef>
#include <cstdint>

#include "catgs/scene_io.hpp"
#include "scene_checks.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    return catgs::fuzz::fuzz_scene_reader(data, size, catgs::read_ply, [](const catgs::Scene&) {});
}
