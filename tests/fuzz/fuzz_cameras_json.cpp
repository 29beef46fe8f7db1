// libFuzzer target: catgs::read_cameras_json (graphdeco cameras.json) on arbitrary bytes.

#include <cstddef>
#include <cstdint>

#include "camera_checks.hpp"
#include "catgs/error.hpp"
#include "catgs/trajectory.hpp"
#include "fuzz_util.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    if (size > catgs::fuzz::kMaxInputBytes) return -1;
    static catgs::fuzz::MemoryFile file;
    const std::string& path = file.write(data, size);
    try {
        catgs::fuzz::check_cameras(catgs::read_cameras_json(path), "cameras.json");
    } catch (const catgs::Error& e) {
        catgs::fuzz::check_file_message(e.what(), path);
    }
    return 0;
}
