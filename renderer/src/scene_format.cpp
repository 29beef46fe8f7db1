// Format detection by content and the dispatch from a format to its reader.

#include "catgs/scene_format.hpp"

#include <algorithm>
#include <array>
#include <cctype>
#include <cstdio>
#include <filesystem>
#include <string>
#include <string_view>

#include "scene_io_detail.hpp"

namespace catgs {

namespace {

/// A PLY header longer than this is not searched for the compressed layout's elements: real
/// headers are under 4 KiB (a 3-degree SH PLY has 62 property lines), and read_ply checks
/// whatever it holds anyway.
constexpr std::size_t kSniffBytes = std::size_t{64} << 10;
/// How many leading bytes an "unknown format" message shows, in hex.
constexpr std::size_t kShownBytes = 8;

/// The extensions of scene files, for the message about a spec that names none.
constexpr std::array<std::string_view, 6> kSceneExtensions = {".ply", ".splat", ".spz", ".sog", ".json", ".glb"};

constexpr std::string_view kGzipMagic = "\x1f\x8b";
constexpr std::string_view kSpzV4Magic = "NGSP";
constexpr std::string_view kZipMagic = "PK\x03\x04";
constexpr std::string_view kGlbMagic = "glTF";

std::string lower(std::string text) {
    std::transform(text.begin(), text.end(), text.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    return text;
}

std::string extension_of(const std::string& path) {
    return lower(std::filesystem::path(path).extension().string());
}

/// SuperSplat's compressed PLY is a PLY whose header declares an element "chunk" (the
/// per-256-Gaussian bounds) and a vertex property "packed_position".
bool is_compressed_ply_header(std::string_view head) {
    bool chunk_element = false, packed_position = false;
    while (!head.empty()) {
        const std::size_t end = head.find('\n');
        std::string_view line = head.substr(0, end);
        if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
        if (line == "end_header") break;
        if (line.starts_with("element chunk ")) chunk_element = true;
        if (line.starts_with("property ") && line.ends_with(" packed_position")) packed_position = true;
        if (end == std::string_view::npos) break;
        head.remove_prefix(end + 1);
    }
    return chunk_element && packed_position;
}

std::string hex_bytes(std::string_view bytes) {
    std::string out;
    for (std::size_t i = 0; i < bytes.size() && i < kShownBytes; ++i) {
        char hex[4];
        std::snprintf(hex, sizeof(hex), "%s%02x", i ? " " : "", static_cast<unsigned char>(bytes[i]));
        out += hex;
    }
    return out.empty() ? "an empty file" : "first bytes " + out;
}

std::string read_head(const std::string& path) {
    io::FileReader in(path);
    const std::size_t want = static_cast<std::size_t>(std::min<std::uint64_t>(in.size(), kSniffBytes));
    if (want > 0 && !in.require(want)) io::fail(path, "file ends while reading its first bytes", io::at_offset(0));
    return std::string(reinterpret_cast<const char*>(in.data()), want);
}

[[noreturn]] void unknown_format(const std::string& path, const std::string& extension, const std::string& seen) {
    io::fail(
        path,
        "unknown scene format; expected a PLY (.ply, .compressed.ply), .splat, .spz, .sog, meta.json or .glb "
        "file, or builtin:city",
        (extension.empty() ? std::string("no file extension") : "extension " + io::quote(extension)) + ", " + seen);
}

SceneFormat format_of(std::string_view head) {
    if (head.starts_with("ply\n") || head.starts_with("ply\r\n"))
        return is_compressed_ply_header(head) ? SceneFormat::compressed_ply : SceneFormat::ply;
    if (head.starts_with(kGzipMagic) || head.starts_with(kSpzV4Magic)) return SceneFormat::spz;
    if (head.starts_with(kZipMagic)) return SceneFormat::sog;
    if (head.starts_with(kGlbMagic)) return SceneFormat::glb;
    const std::size_t first = head.find_first_not_of(" \t\r\n");
    if (first != std::string_view::npos && head[first] == '{') return SceneFormat::sog_meta;
    return SceneFormat::unknown;
}

}  // namespace

std::string_view scene_format_name(SceneFormat format) {
    switch (format) {
        case SceneFormat::unknown:
            return "unknown";
        case SceneFormat::ply:
            return "PLY";
        case SceneFormat::compressed_ply:
            return "compressed PLY";
        case SceneFormat::splat:
            return ".splat";
        case SceneFormat::spz:
            return ".spz";
        case SceneFormat::sog:
            return ".sog";
        case SceneFormat::sog_meta:
            return "SOG meta.json";
        case SceneFormat::glb:
            return ".glb";
    }
    return "unknown";
}

SceneFormat detect_scene_format(const std::string& path) {
    // .splat has no signature: its first bytes are a float position, which may look like
    // anything (1 in 65536 files would start like gzip), so its extension decides.
    if (extension_of(path) == ".splat") return SceneFormat::splat;
    return format_of(read_head(path));
}

Scene read_scene_file(const std::string& path, const LoadOptions& options, LoadReport* report) {
    const std::string extension = extension_of(path);
    // A missing file named like no scene at all is more likely a mistyped spec than a lost
    // file: say which formats there are.
    const bool scene_extension =
        std::find(kSceneExtensions.begin(), kSceneExtensions.end(), extension) != kSceneExtensions.end();
    std::error_code ignored;
    if (!scene_extension && !std::filesystem::exists(path, ignored)) unknown_format(path, extension, "no such file");
    const SceneFormat format = detect_scene_format(path);
    switch (format) {
        case SceneFormat::ply:
            return read_ply(path, options, report);
        case SceneFormat::compressed_ply:
            return read_compressed_ply(path, options, report);
        case SceneFormat::splat:
            return read_splat(path, options, report);
        case SceneFormat::spz:
            return read_spz(path, options, report);
        case SceneFormat::sog:
        case SceneFormat::sog_meta:
            return read_sog(path, options, report);
        case SceneFormat::glb:
            return read_glb(path, options, report);
        case SceneFormat::unknown:
            break;
    }
    unknown_format(path, extension, hex_bytes(read_head(path)));
}

}  // namespace catgs
