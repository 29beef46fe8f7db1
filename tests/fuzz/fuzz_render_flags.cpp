// libFuzzer target: catgs-render's --background r,g,b parser (parse_background in
// renderer/tools/catgs_render.cpp, file-local, so the tool's source is compiled in here with
// its main() renamed).

#include <cstddef>
#include <cstdint>
#include <string>

#define main catgs_render_main
#include "../../renderer/tools/catgs_render.cpp"
#undef main

#include "fuzz_util.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    if (size > 4096) return -1;
    const std::string text = catgs::fuzz::as_string(data, size);
    try {
        const std::array<float, 3> rgb = parse_background(text);
        for (float c : rgb) catgs::fuzz::require(c >= 0.0f && c <= 1.0f, "background outside [0, 1] accepted");
    } catch (const catgs::Error& e) {
        catgs::fuzz::require(std::string(e.what()).rfind("--background '", 0) == 0,
                             "error does not name --background: " + std::string(e.what()));
    }
    return 0;
}
