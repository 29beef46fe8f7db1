// libFuzzer target: catgs-bench's --sweep parser (cli::parse_sweep: "name: flags; name: flags",
// or @FILE with one entry per line), each entry's flags parsed by CLI11 and applied by
// cli::apply_pipeline_flags. An input with a newline is passed as the contents of an @FILE
// (where lines are entries), any other as the flag's text. Inputs of more than kMaxEntries
// entries are skipped: each entry builds a CLI11 parser, which dominates the cost of a run.

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "catgs/error.hpp"
#include "catgs/render_options.hpp"
#include "cli_options.hpp"
#include "fuzz_util.hpp"

namespace {

constexpr std::size_t kMaxEntries = 4;

void check(const std::string& text) {
    try {
        const std::vector<catgs::cli::SweepEntry> configs = catgs::cli::parse_sweep(text);
        catgs::fuzz::require(!configs.empty(), "an empty sweep accepted");
        for (const catgs::cli::SweepEntry& c : configs) {
            const catgs::CatgsOptions& o = c.options.catgs;
            catgs::fuzz::require(o.window >= 1 && o.window <= catgs::kMaxWindow, "window outside 1..16 accepted");
            catgs::fuzz::require(o.split_k <= (1u << 24), "split k above 2^24 accepted");
        }
    } catch (const catgs::Error&) {
        // Sweep errors quote the entry as written (it may hold anything): any message.
    }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    if (size > 512) return -1;  // a few short entries: long inputs only slow the search down
    static catgs::fuzz::MemoryFile file;
    const std::string text = catgs::fuzz::as_string(data, size);
    const auto separators = std::count(text.begin(), text.end(), ';') + std::count(text.begin(), text.end(), '\n');
    if (static_cast<std::size_t>(separators) >= kMaxEntries) return -1;
    if (text.find('\n') != std::string::npos)
        check("@" + file.write(data, size));
    else if (text.empty() || text[0] != '@')  // a leading '@' names a file to read (/dev/zero...)
        check(text);
    return 0;
}
