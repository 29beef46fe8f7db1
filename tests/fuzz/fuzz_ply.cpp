// libFuzzer target: catgs::read_ply (graphdeco PLY, binary LE/BE and ASCII) on arbitrary bytes.
// Each input is read twice: with the defaults (invalid records are errors) and with
// drop_invalid and without recentring, so both paths of SceneBuilder are searched.

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
        const catgs::Scene scene = catgs::read_ply(path, options, &report);
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
