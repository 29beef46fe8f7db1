#include "catgs/common/files.hpp"

#include <optional>

#include "catgs/error.hpp"
#include "catgs/regular_file.hpp"

namespace catgs {

std::string read_file(const std::string& path, const std::string& flag) {
    std::string problem;
    std::optional<std::string> bytes = read_regular_file(path, kMaxSmallFileBytes, problem);
    if (!bytes) throw Error(flag + " '" + path + "': cannot read the file: " + problem);
    return std::move(*bytes);
}

std::string read_token(const std::string& path) {
    std::string token = read_file(path, "--token-file");
    token = token.substr(0, token.find('\n'));
    while (!token.empty() && (token.back() == '\r' || token.back() == ' ')) token.pop_back();
    if (token.empty()) throw Error("--token-file '" + path + "': the first line is empty");
    return token;
}

}  // namespace catgs
