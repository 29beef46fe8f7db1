#include "catgs/common/files.hpp"

#include <fstream>
#include <sstream>

#include "catgs/error.hpp"

namespace catgs {

std::string read_file(const std::string& path, const std::string& flag) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw Error(flag + " '" + path + "': cannot read the file");
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
}

std::string read_token(const std::string& path) {
    std::ifstream in(path);
    if (!in) throw Error("--token-file '" + path + "': cannot read the file");
    std::string token;
    std::getline(in, token);
    while (!token.empty() && (token.back() == '\r' || token.back() == ' ')) token.pop_back();
    if (token.empty()) throw Error("--token-file '" + path + "': the first line is empty");
    return token;
}

}  // namespace catgs
