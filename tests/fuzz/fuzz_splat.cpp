// libFuzzer target: catgs::read_splat (32-byte antimatter15 records) on arbitrary bytes, with
// and without drop_invalid.

#include <cstddef>
#include <cstdint>

#include "catgs/error.hpp"
#include "catgs/scene_io.hpp"
#include "fuzz_util.hpp"
#include "scene_checks.hpp"

namespace {

void read_once(const std::string& path, bool drop_invalid) {
    catgs::LoadOptions options;
    options.drop_invalid = drop_invalid;
    options.recentre = !drop_invalid;
    options.max_records = catgs::fuzz::kMaxRecords;
    catgs::LoadReport report;
    try {
        const catgs::Scene scene = catgs::read_splat(path, options, &report);
        catgs::fuzz::require(scene.sh_degree == 0, ".splat scene with SH degree > 0");
        catgs::fuzz::check_scene(scene, report, options);
    } catch (const catgs::Error& e) {
        catgs::fuzz::check_file_message(e.what(), path);
    }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    if (size > catgs::fuzz::kMaxInputBytes) return -1;
    static catgs::fuzz::MemoryFile file;
    const std::string& path = file.write(data, size);
    read_once(path, false);
    read_once(path, true);
    return 0;
}
