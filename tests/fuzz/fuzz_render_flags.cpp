// libFuzzer target: catgs-render's --background r,g,b parser (cli::parse_background).

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>

#include "catgs/error.hpp"
#include "cli_options.hpp"
#include "fuzz_util.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    if (size > 4096) return -1;
    const std::string text = catgs::fuzz::as_string(data, size);
    try {
        const std::array<float, 3> rgb = catgs::cli::parse_background(text);
        for (float c : rgb) catgs::fuzz::require(c >= 0.0f && c <= 1.0f, "background outside [0, 1] accepted");
    } catch (const catgs::Error& e) {
        catgs::fuzz::require(std::string(e.what()).rfind("--background '", 0) == 0,
                             "error does not name --background: " + std::string(e.what()));
    }
    return 0;
}
