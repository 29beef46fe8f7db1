// libFuzzer target: the --token-file reader of catgs-server (catgs::read_token, the bearer
// token's first line) on arbitrary file contents.

#include <cstddef>
#include <cstdint>
#include <string>

#include "catgs/common/files.hpp"
#include "catgs/error.hpp"
#include "fuzz_util.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    if (size > catgs::fuzz::kMaxInputBytes) return -1;
    static catgs::fuzz::MemoryFile file;
    const std::string& path = file.write(data, size);
    using catgs::fuzz::require;
    try {
        const std::string token = catgs::read_token(path);
        require(!token.empty(), "empty token accepted");
        require(token.find('\n') == std::string::npos, "token spans lines");
        require(token.back() != ' ' && token.back() != '\r', "token keeps trailing blanks");
        const std::string contents = catgs::fuzz::as_string(data, size);
        require(contents.rfind(token, 0) == 0, "token is not the start of the file");
    } catch (const catgs::Error& e) {
        catgs::fuzz::check_one_line(e.what());
        require(std::string(e.what()).rfind("--token-file '" + path + "': ", 0) == 0,
                "token error does not name the flag and file: " + std::string(e.what()));
    }
    return 0;
}
