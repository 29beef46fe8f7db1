// The web endpoint's pure rules, kept apart from Beast so that they are unit-tested alone:
// which file a URL names (and which it must not), content types, query parameters, and how a
// gRPC status becomes a WebSocket close code or an HTTP status.
#include <filesystem>
#include <system_error>

#include "catgs/server/web_endpoint.hpp"

namespace catgs::server::web {
namespace {

namespace fs = std::filesystem;

/// A close code of 4000 + a gRPC code: 4000-4999 is the range RFC 6455 leaves to applications.
constexpr int kCloseCodeBase = 4000;
constexpr int kCloseNormal = 1000;

int hex_value(char c) {
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
}

/// %XX-decodes `in`; false on a malformed escape. '+' stays '+' (this is a path, and the
/// query values we read are tokens, which never contain '+' unescaped by our page).
bool percent_decode(const std::string& in, std::string* out) {
    out->clear();
    for (std::size_t i = 0; i < in.size(); ++i) {
        if (in[i] != '%') {
            out->push_back(in[i]);
            continue;
        }
        const int high = i + 1 < in.size() ? hex_value(in[i + 1]) : -1;
        const int low = i + 2 < in.size() ? hex_value(in[i + 2]) : -1;
        if (high < 0 || low < 0) return false;
        out->push_back(static_cast<char>(high * 16 + low));
        i += 2;
    }
    return true;
}

bool is_within(const fs::path& root, const fs::path& path) {
    auto r = root.begin(), p = path.begin();
    for (; r != root.end(); ++r, ++p)
        if (p == path.end() || *r != *p) return false;
    return true;
}

}  // namespace

const char* code_name(grpc::StatusCode code) {
    switch (code) {
        case grpc::StatusCode::OK:
            return "OK";
        case grpc::StatusCode::CANCELLED:
            return "CANCELLED";
        case grpc::StatusCode::UNKNOWN:
            return "UNKNOWN";
        case grpc::StatusCode::INVALID_ARGUMENT:
            return "INVALID_ARGUMENT";
        case grpc::StatusCode::DEADLINE_EXCEEDED:
            return "DEADLINE_EXCEEDED";
        case grpc::StatusCode::NOT_FOUND:
            return "NOT_FOUND";
        case grpc::StatusCode::ALREADY_EXISTS:
            return "ALREADY_EXISTS";
        case grpc::StatusCode::PERMISSION_DENIED:
            return "PERMISSION_DENIED";
        case grpc::StatusCode::RESOURCE_EXHAUSTED:
            return "RESOURCE_EXHAUSTED";
        case grpc::StatusCode::FAILED_PRECONDITION:
            return "FAILED_PRECONDITION";
        case grpc::StatusCode::ABORTED:
            return "ABORTED";
        case grpc::StatusCode::OUT_OF_RANGE:
            return "OUT_OF_RANGE";
        case grpc::StatusCode::UNIMPLEMENTED:
            return "UNIMPLEMENTED";
        case grpc::StatusCode::INTERNAL:
            return "INTERNAL";
        case grpc::StatusCode::UNAVAILABLE:
            return "UNAVAILABLE";
        case grpc::StatusCode::DATA_LOSS:
            return "DATA_LOSS";
        case grpc::StatusCode::UNAUTHENTICATED:
            return "UNAUTHENTICATED";
        default:
            return "UNKNOWN";
    }
}

int close_code_for(grpc::StatusCode code) {
    return code == grpc::StatusCode::OK ? kCloseNormal : kCloseCodeBase + static_cast<int>(code);
}

std::string status_text(const grpc::Status& status, std::size_t max_bytes) {
    std::string text = code_name(status.error_code());
    if (!status.error_message().empty()) text += ": " + status.error_message();
    if (text.size() <= max_bytes) return text;
    // Back up over UTF-8 continuation bytes (10xxxxxx) so the cut never splits a character:
    // browsers fail a connection whose close reason is not valid UTF-8.
    std::size_t cut = max_bytes;
    while (cut > 0 && (static_cast<unsigned char>(text[cut]) & 0xC0) == 0x80) --cut;
    text.resize(cut);
    return text;
}

int http_status_for(grpc::StatusCode code) {
    switch (code) {
        case grpc::StatusCode::OK:
            return 200;
        case grpc::StatusCode::INVALID_ARGUMENT:
        case grpc::StatusCode::FAILED_PRECONDITION:
        case grpc::StatusCode::OUT_OF_RANGE:
            return 400;
        case grpc::StatusCode::UNAUTHENTICATED:
            return 401;
        case grpc::StatusCode::PERMISSION_DENIED:
            return 403;
        case grpc::StatusCode::NOT_FOUND:
            return 404;
        case grpc::StatusCode::RESOURCE_EXHAUSTED:
            return 429;
        case grpc::StatusCode::UNAVAILABLE:
            return 503;
        default:
            return 500;
    }
}

std::optional<std::string> query_parameter(const std::string& target, const std::string& name) {
    const std::size_t question = target.find('?');
    if (question == std::string::npos) return std::nullopt;
    std::size_t begin = question + 1;
    while (begin <= target.size()) {
        std::size_t end = target.find('&', begin);
        if (end == std::string::npos) end = target.size();
        const std::string pair = target.substr(begin, end - begin);
        const std::size_t eq = pair.find('=');
        if (pair.substr(0, eq) == name) {
            std::string value;
            if (eq == std::string::npos) return value;
            if (!percent_decode(pair.substr(eq + 1), &value)) return std::nullopt;
            return value;
        }
        begin = end + 1;
    }
    return std::nullopt;
}

StaticPath resolve_static_path(const std::string& root, const std::string& target) {
    StaticPath result;
    auto refuse = [&](int status, std::string why) {
        result.http_status = status;
        result.error = std::move(why);
        return result;
    };
    std::string raw = target.substr(0, target.find('?'));
    raw = raw.substr(0, raw.find('#'));
    std::string decoded;
    if (!percent_decode(raw, &decoded)) return refuse(400, "path '" + raw + "': malformed %-escape");
    if (decoded.empty() || decoded[0] != '/') return refuse(400, "path '" + raw + "': must start with '/'");
    if (decoded.find('\0') != std::string::npos || decoded.find('\\') != std::string::npos)
        return refuse(400, "path '" + raw + "': NUL and backslash are not allowed");
    if (decoded.back() == '/') decoded += "index.html";

    fs::path relative;
    std::size_t begin = 1;
    while (begin <= decoded.size()) {
        std::size_t end = decoded.find('/', begin);
        if (end == std::string::npos) end = decoded.size();
        const std::string segment = decoded.substr(begin, end - begin);
        // "." and ".." would walk out of the root; hidden files (".git", ".env") are never
        // part of a built viewer.
        if (segment.empty() || segment[0] == '.')
            return refuse(400, "path '" + raw + "': empty, '.', '..' and hidden segments are not allowed");
        relative /= segment;
        begin = end + 1;
    }
    std::error_code ec;
    const fs::path real = fs::canonical(fs::path(root) / relative, ec);
    if (ec) return refuse(404, "path '" + raw + "': no such file");
    // canonical() resolved every symlink: a link pointing outside the root lands outside.
    if (!is_within(fs::path(root), real)) return refuse(404, "path '" + raw + "': outside the web root");
    if (!fs::is_regular_file(real, ec)) return refuse(404, "path '" + raw + "': not a file");
    result.path = real.string();
    return result;
}

std::string content_type_for(const std::string& path) {
    static const std::pair<const char*, const char*> kTypes[] = {
        {".html", "text/html; charset=utf-8"},
        {".js", "text/javascript; charset=utf-8"},
        {".mjs", "text/javascript; charset=utf-8"},
        {".css", "text/css; charset=utf-8"},
        {".json", "application/json"},
        {".map", "application/json"},
        {".txt", "text/plain; charset=utf-8"},
        {".svg", "image/svg+xml"},
        {".png", "image/png"},
        {".jpg", "image/jpeg"},
        {".jpeg", "image/jpeg"},
        {".webp", "image/webp"},
        {".ico", "image/x-icon"},
        {".wasm", "application/wasm"},
        {".woff2", "font/woff2"},
        {".csv", "text/csv; charset=utf-8"},
    };
    const std::string extension = fs::path(path).extension().string();
    for (const auto& [ext, type] : kTypes)
        if (extension == ext) return type;
    return "application/octet-stream";
}

}  // namespace catgs::server::web
