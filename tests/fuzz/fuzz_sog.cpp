// libFuzzer target: catgs::read_sog (PlayCanvas SOG: a zip of WebP textures and meta.json, or
// an unbundled meta.json) on arbitrary bytes, with and without drop_invalid
// (fuzz_scene_reader). The seeds are .sog files splat-transform 3.7.0 wrote (SH degree 0..3,
// meta.json's numbers shortened by make_seed_corpus.py, as each execution parses it twice),
// so mutations reach the zip, meta.json and WebP layers; an unbundled meta.json names files
// that do not exist beside the in-memory input, so that path ends at its first texture.

#include <cstddef>
#include <cstdint>

#include "catgs/scene_io.hpp"
#include "scene_checks.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    return catgs::fuzz::fuzz_scene_reader(data, size, catgs::read_sog, [](const catgs::Scene& scene) {
        catgs::fuzz::require(scene.sh_degree >= 0 && scene.sh_degree <= catgs::kMaxShDegree,
                             "SOG scene with SH degree outside 0..3");
    });
}
