// libFuzzer target: the command-line value parsers of catgs-render and catgs-bench that take
// free text: --grid NxM and --up (scene_ops.hpp), --culling, --cache, --precision, and the
// pipeline flags of a --sweep entry ("name: --split 64 --cache speculative ..."), parsed by
// CLI11 and applied by cli::apply_pipeline_flags exactly as catgs-bench's parse_sweep does.

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

#include "catgs/cache.hpp"
#include "catgs/error.hpp"
#include "catgs/render_options.hpp"
#include "catgs/renderer.hpp"
#include "catgs/scene_ops.hpp"
#include "cli_options.hpp"
#include "fuzz_util.hpp"

namespace {

using catgs::fuzz::require;

template <typename F>
void expect_value_or_error(F&& parse) {
    try {
        parse();
    } catch (const catgs::Error& e) {
        catgs::fuzz::check_one_line(e.what());
    }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    // Flag values and a sweep entry's flags are short; long inputs only slow the search down
    // (CLI11's cost grows with the number of words).
    if (size > 512) return -1;
    const std::string text = catgs::fuzz::as_string(data, size);
    // Flag values are single arguments (one line); only the sweep entry below can span lines.
    if (text.find('\n') == std::string::npos) {
        expect_value_or_error([&] {
            const auto [x, y] = catgs::parse_grid(text);
            require(x >= 1 && x <= 64 && y >= 1 && y <= 64, "grid outside 1..64 accepted");
        });
        expect_value_or_error([&] {
            const int axis = catgs::parse_up_axis(text);
            require(axis >= 0 && axis <= 2, "up axis outside 0..2");
        });
        expect_value_or_error([&] { (void)catgs::parse_culling(text); });
        expect_value_or_error([&] { (void)catgs::parse_cache_mode(text); });
        expect_value_or_error([&] { (void)catgs::parse_precision(text); });
    }

    // A sweep entry's flags. The parser is reused for kParserRuns runs (building it is most of
    // the cost of a run): CLI11 clears its results at each parse and the flags start from their
    // defaults. Not for ever: CLI11 2.1's clear() keeps the parse order list, which grows by
    // one entry per option parsed.
    constexpr int kParserRuns = 1024;
    static catgs::cli::PipelineFlags flags;
    static std::unique_ptr<CLI::App> app;
    static int runs = 0;
    if (!app || ++runs % kParserRuns == 0) {
        app = std::make_unique<CLI::App>();
        catgs::cli::add_pipeline_flags(*app, flags);
    }
    flags = catgs::cli::PipelineFlags{};
    try {
        app->parse(text, false);
    } catch (const CLI::ParseError&) {
        return 0;
    }
    catgs::RenderOptions options;
    try {
        catgs::cli::apply_pipeline_flags(flags, options);
    } catch (const catgs::Error& e) {
        require(std::string(e.what()).size() > 0, "empty error message");
        return 0;
    }
    const catgs::CatgsOptions& c = options.catgs;
    require(c.window >= 1 && c.window <= catgs::kMaxWindow, "window outside 1..16 accepted");
    require(c.split_k <= (1u << 24), "split k above 16777216 accepted");
    require(c.split_tail_transmittance >= catgs::kMinTransmittance && c.split_tail_transmittance < 1.0,
            "split tail outside [1e-4, 1) accepted");
    require(c.guard_px >= 0 && c.guard_px <= 64 && c.guard_translation >= 0 && c.guard_translation <= 100,
            "guard outside its range accepted");
    (void)catgs::cli::describe_pipeline(options);
    return 0;
}
