// PlayCanvas SOG, version 2 of its meta.json (what splat-transform 1.x-3.x writes): a zip of
// WebP textures plus meta.json (.sog), or the unbundled meta.json beside its .webp files.
// Written from the format's description in the PlayCanvas docs and splat-transform's sources.
//
// Texel i of every texture holds Gaussian i:
//   means_l/means_u  16-bit (low, high byte) steps between meta means.mins and means.maxs of
//                    sign(v) * ln(|v| + 1), per axis in r, g, b
//   quats            the three smallest components of the unit quaternion, each as
//                    byte / 255 * 2 - 1 divided by sqrt 2, in r, g, b; a = 252 + the index of
//                    the largest (w, x, y, z order), which is reconstructed non-negative
//   scales           r, g, b index the 256-entry scales.codebook (log scale)
//   sh0              r, g, b index sh0.codebook (f_dc); a is the opacity, byte / 255
//   shN labels       r | g << 8 index a palette entry in the centroids texture: entry e is
//                    texels [(e % 64) * coeffs, +coeffs) of row e / 64, r, g, b of each texel
//                    indexing shN.codebook
// Coordinates are the PLY convention (RDF: x right, y down, z forward), which catgs keeps.

#include <webp/decode.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "catgs/scene_io.hpp"
#include "scene_io_detail.hpp"
#include "sog_files.hpp"

namespace catgs {

namespace {

using io::fail;
using io::quote;
using nlohmann::json;
using sog::at_key;
using sog::FilePtr;
using sog::open_regular;
using sog::read_all;
using sog::SogFiles;

constexpr int kSogVersion = 2;
constexpr const char* kMetaName = "meta.json";
/// meta.json holds three or four codebooks of 256 numbers and a few file names (~20 KB);
/// anything near this is not a SOG meta.json, and it is refused before it is read.
constexpr std::uint64_t kMaxMetaBytes = std::uint64_t{4} << 20;
/// Deeper JSON than this is not SOG's; the cap keeps a hostile nesting from costing stack.
constexpr int kMaxJsonDepth = 16;
/// WebP's own limit is 16383 x 16383 texels; splat-transform refuses to write more.
constexpr std::uint64_t kMaxTexels = std::uint64_t{16383} * 16383;
/// splat-transform pads each texture to multiples of 4 in both dimensions (at most
/// ~8 sqrt(count) + 16 extra texels); other writers may round each dimension up to a power of
/// two, which at most quadruples it. Larger textures are refused before they are decoded.
constexpr std::uint64_t kTexelOverallocation = 4;
constexpr std::uint64_t kTexelSlack = 65536;
/// A WebP never needs more than this many bytes per texel (lossless RGBA stores at most
/// 4 bytes of literals per texel plus its prefix codes); the header slack covers the RIFF
/// header and metadata chunks. A zip entry that declares more is refused before inflating.
constexpr std::uint64_t kMaxWebpBytesPerTexel = 5;
constexpr std::uint64_t kWebpHeaderSlack = 64 << 10;
/// Real SOG files take 5-15 bytes per Gaussian (truck: 13), an all-identical scene still
/// about one; a count beyond this many Gaussians per stored byte cannot be a real capture,
/// only a tiny file asking for gigabytes of textures and scene.
constexpr std::uint64_t kMaxGaussiansPerByte = 1024;
/// The SH palette: 64 entries per centroids row, addressed by 16-bit labels.
constexpr std::uint64_t kPaletteColumns = 64;
constexpr std::uint64_t kMaxPaletteEntries = 65536;
constexpr std::size_t kMaxCodebookEntries = 256;
/// The quats texture's alpha is 252 + the index of the largest component.
constexpr int kQuatTagFirst = 252;
constexpr double kMeansSteps = 65535.0;
constexpr double kByteSteps = 255.0;
constexpr int kRgba = 4;

/// splat-transform's reader clamps the opacity into (0, 1) by this before taking its logit.
constexpr double kOpacityClamp = 1e-6;

// The decoded values are rounded to float and the opacity turned into a float logit, exactly
// as splat-transform's own reader does before it writes a PLY: a .sog and the PLY that
// splat-transform decodes from it then load to identical scenes (and the same count: an
// opacity at the 1/255 cut must fall on the same side of it in both).
constexpr io::Encoding kSogEncoding{.log_scale = true, .logit_opacity = true, .noun = "field", .nouns = "fields"};

double as_float(double v) {
    return static_cast<double>(static_cast<float>(v));
}

// ---------------------------------------------------------------------------------------
// meta.json

struct SogMeta {
    std::uint64_t count = 0;
    std::array<double, 3> means_min{}, means_range{};
    std::vector<double> scales_codebook, sh0_codebook, shn_codebook;
    std::string means_l, means_u, quats, scales, sh0, centroids, labels;
    int sh_degree = 0;
    std::uint64_t palette_entries = 0;
};

class MetaReader {
public:
    MetaReader(const std::string& path, const json& root) : path_(path), root_(root) {}

    const json& member(const json& object, const std::string& key, const std::string& name) const {
        if (!object.is_object()) fail(path_, "expected an object", at_key(key));
        auto it = object.find(name);
        if (it == object.end()) fail(path_, "missing key", at_key(key.empty() ? name : key + "." + name));
        return *it;
    }
    const json& at(const std::string& key) const {
        const json* node = &root_;
        std::string done;
        for (std::size_t begin = 0; begin <= key.size();) {
            std::size_t end = key.find('.', begin);
            if (end == std::string::npos) end = key.size();
            node = &member(*node, done, key.substr(begin, end - begin));
            done = key.substr(0, end);
            begin = end + 1;
        }
        return *node;
    }
    double number(const json& value, const std::string& key) const {
        if (!value.is_number()) fail(path_, std::string("expected a number, found ") + value.type_name(), at_key(key));
        const double v = value.get<double>();
        if (!std::isfinite(v)) fail(path_, "number " + io::format_value(v) + " is not finite", at_key(key));
        return v;
    }
    std::uint64_t unsigned_integer(const std::string& key) const {
        const json& value = at(key);
        if (!value.is_number_unsigned())
            fail(path_, std::string("expected an unsigned integer, found ") + value.type_name(), at_key(key));
        return value.get<std::uint64_t>();
    }
    std::vector<double> numbers(const std::string& key, std::size_t min_size, std::size_t max_size) const {
        const json& value = at(key);
        if (!value.is_array() || value.size() < min_size || value.size() > max_size)
            fail(path_,
                 "expected an array of " + std::to_string(min_size) +
                     (max_size > min_size ? ".." + std::to_string(max_size) : "") + " numbers",
                 at_key(key));
        std::vector<double> out;
        out.reserve(value.size());
        for (std::size_t i = 0; i < value.size(); ++i) {
            // The element's key is built only for a message: a codebook has 256 elements.
            const json& item = value[i];
            out.push_back(item.is_number() && std::isfinite(item.get<double>())
                              ? item.get<double>()
                              : number(item, key + "[" + std::to_string(i) + "]"));
        }
        return out;
    }
    /// A codebook, rounded to float as splat-transform holds it.
    std::vector<double> codebook(const std::string& key) const {
        std::vector<double> out = numbers(key, 1, kMaxCodebookEntries);
        for (double& v : out) {
            v = as_float(v);
            if (!std::isfinite(v)) fail(path_, "codebook value overflows float", at_key(key));
        }
        return out;
    }
    std::string file(const std::string& key, std::size_t index, std::size_t files) const {
        const json& value = at(key);
        const std::string item = key + "[" + std::to_string(index) + "]";
        if (!value.is_array() || value.size() != files)
            fail(path_, "expected an array of " + std::to_string(files) + " file names", at_key(key));
        if (!value[index].is_string()) fail(path_, "expected a file name", at_key(item));
        return value[index].get<std::string>();
    }

private:
    const std::string& path_;
    const json& root_;
};

json parse_json(const std::string& path, const std::vector<unsigned char>& text) {
    try {
        return json::parse(text.begin(), text.end(), [&](int depth, json::parse_event_t, json&) {
            if (depth > kMaxJsonDepth)
                fail(path, "meta.json nests deeper than " + std::to_string(kMaxJsonDepth) + " levels", "meta.json");
            return true;
        });
    } catch (const json::exception& e) {
        // parse_error for bad syntax, out_of_range for a number beyond double.
        std::string message = e.what();
        // "[json.exception.parse_error.101] parse error at ...": the tag means nothing to a user.
        if (auto bracket = message.find("] "); bracket != std::string::npos) message.erase(0, bracket + 2);
        const auto* syntax = dynamic_cast<const json::parse_error*>(&e);
        fail(path, "meta.json is not valid JSON: " + message,
             syntax ? "meta.json, byte " + std::to_string(syntax->byte) : "meta.json");
    }
}

SogMeta read_meta(const std::string& path, const json& root) {
    MetaReader meta(path, root);
    if (!root.is_object()) fail(path, "meta.json is not a JSON object", "meta.json");
    if (!root.contains("version"))
        fail(path, "meta.json has no 'version': SOG version 1 is not supported; convert it again with splat-transform",
             "meta.json");
    if (meta.unsigned_integer("version") != kSogVersion)
        fail(path, "unsupported SOG version " + std::to_string(root["version"].get<std::uint64_t>()) + "; expected 2",
             at_key("version"));
    SogMeta m;
    m.count = meta.unsigned_integer("count");
    if (m.count == 0) fail(path, "no Gaussians: meta.json declares a count of 0", at_key("count"));
    if (m.count > kMaxTexels)
        fail(path, "count " + std::to_string(m.count) + " is more than a WebP texture can hold (16383 x 16383)",
             at_key("count"));
    const std::vector<double> mins = meta.numbers("means.mins", 3, 3);
    const std::vector<double> maxs = meta.numbers("means.maxs", 3, 3);
    for (int a = 0; a < 3; ++a) {
        m.means_min[a] = mins[a];
        // As splat-transform reads it: a zero range (every Gaussian on one plane) steps by 1.
        m.means_range[a] = maxs[a] - mins[a] != 0.0 ? maxs[a] - mins[a] : 1.0;
    }
    m.means_l = meta.file("means.files", 0, 2);
    m.means_u = meta.file("means.files", 1, 2);
    m.quats = meta.file("quats.files", 0, 1);
    m.scales = meta.file("scales.files", 0, 1);
    m.sh0 = meta.file("sh0.files", 0, 1);
    m.scales_codebook = meta.codebook("scales.codebook");
    m.sh0_codebook = meta.codebook("sh0.codebook");
    if (root.contains("shN")) {
        const std::uint64_t bands = meta.unsigned_integer("shN.bands");
        if (bands > static_cast<std::uint64_t>(kMaxShDegree))
            fail(path, "SH bands " + std::to_string(bands) + " is not 0..3", at_key("shN.bands"));
        m.sh_degree = static_cast<int>(bands);
    }
    if (m.sh_degree > 0) {
        m.palette_entries = meta.unsigned_integer("shN.count");
        if (m.palette_entries == 0 || m.palette_entries > kMaxPaletteEntries)
            fail(path, "palette of " + std::to_string(m.palette_entries) + " entries is not 1..65536",
                 at_key("shN.count"));
        m.shn_codebook = meta.codebook("shN.codebook");
        m.centroids = meta.file("shN.files", 0, 2);
        m.labels = meta.file("shN.files", 1, 2);
    }
    return m;
}

// ---------------------------------------------------------------------------------------
// Textures

struct Texture {
    std::vector<unsigned char> rgba;
    std::uint64_t width = 0;
};

struct TextureSpec {
    const std::string& name;
    std::string key;  ///< the meta.json key that names it
    std::uint64_t min_texels, max_texels;
    std::string need;  ///< what the minimum is, for a message
};

Texture load_texture(const std::string& path, SogFiles& files, const TextureSpec& spec) {
    const std::vector<unsigned char> bytes =
        files.read(spec.name, kMaxWebpBytesPerTexel * spec.max_texels + kWebpHeaderSlack, spec.key);
    int width = 0, height = 0;
    if (!WebPGetInfo(bytes.data(), bytes.size(), &width, &height))
        fail(path, "not a WebP image", files.where(spec.name));
    const std::uint64_t texels = static_cast<std::uint64_t>(width) * static_cast<std::uint64_t>(height);
    const std::string size = std::to_string(width) + " x " + std::to_string(height);
    if (texels < spec.min_texels)
        fail(path, "WebP of " + size + " texels is too small for " + spec.need, files.where(spec.name));
    if (texels > spec.max_texels)
        fail(path, "WebP of " + size + " texels is larger than " + spec.need + " can use", files.where(spec.name));
    Texture texture;
    texture.width = static_cast<std::uint64_t>(width);
    texture.rgba.resize(static_cast<std::size_t>(texels) * kRgba);
    if (!WebPDecodeRGBAInto(bytes.data(), bytes.size(), texture.rgba.data(), texture.rgba.size(), width * kRgba))
        fail(path, "cannot decode the WebP image", files.where(spec.name));
    return texture;
}

struct SogTextures {
    Texture means_l, means_u, quats, scales, sh0, centroids, labels;
};

SogTextures load_textures(const std::string& path, SogFiles& files, const SogMeta& m) {
    const std::string need = "the " + std::to_string(m.count) + " Gaussians of meta.json 'count'";
    const std::uint64_t max_texels = kTexelOverallocation * m.count + kTexelSlack;
    auto per_gaussian = [&](const std::string& name, const std::string& key) {
        return load_texture(path, files, {name, key, m.count, max_texels, need});
    };
    SogTextures t;
    t.means_l = per_gaussian(m.means_l, "means.files[0]");
    t.means_u = per_gaussian(m.means_u, "means.files[1]");
    t.quats = per_gaussian(m.quats, "quats.files[0]");
    t.scales = per_gaussian(m.scales, "scales.files[0]");
    t.sh0 = per_gaussian(m.sh0, "sh0.files[0]");
    if (m.sh_degree > 0) {
        t.labels = per_gaussian(m.labels, "shN.files[1]");
        const std::uint64_t coefficients = static_cast<std::uint64_t>(sh_coefficient_count(m.sh_degree)) - 1;
        const std::uint64_t rows = (m.palette_entries + kPaletteColumns - 1) / kPaletteColumns;
        const std::uint64_t width = kPaletteColumns * coefficients;
        t.centroids =
            load_texture(path, files,
                         {m.centroids, "shN.files[0]", width * rows, width * (kMaxPaletteEntries / kPaletteColumns),
                          "the " + std::to_string(m.palette_entries) + " entries of meta.json 'shN.count'"});
        if (t.centroids.width != width)
            fail(path,
                 "centroids WebP is " + std::to_string(t.centroids.width) + " texels wide; " +
                     std::to_string(m.sh_degree) + " SH bands need " + std::to_string(width),
                 files.where(m.centroids));
    }
    return t;
}

// ---------------------------------------------------------------------------------------
// Records

std::vector<std::string> sog_field_names(int sh_degree) {
    std::vector<std::string> names = {"x",     "y",     "z",     "scale_0", "scale_1", "scale_2", "opacity",
                                      "rot_0", "rot_1", "rot_2", "rot_3",   "f_dc_0",  "f_dc_1",  "f_dc_2"};
    const int rest = sh_coefficient_count(sh_degree) - 1;
    for (int k = 0; k < rest; ++k)
        for (int c = 0; c < 3; ++c) names.push_back("f_rest_" + std::to_string(k + c * rest));
    return names;
}

/// Inverse of splat-transform's sign(v) * ln(|v| + 1), which spreads the quantisation steps
/// densely near the origin; exp - 1 rather than expm1, as splat-transform computes it.
double inverse_log_transform(double v) {
    const double magnitude = std::exp(std::fabs(v)) - 1.0;
    return v < 0 ? -magnitude : magnitude;
}

class SogDecoder {
public:
    SogDecoder(const std::string& path, const SogMeta& meta, const SogTextures& textures, const SogFiles& files)
        : path_(path), meta_(meta), t_(textures), files_(files) {}

    void decode(std::uint64_t i, double* values) const {
        const std::size_t o = static_cast<std::size_t>(i) * kRgba;
        for (int a = 0; a < 3; ++a) {
            const int step = t_.means_l.rgba[o + a] | (t_.means_u.rgba[o + a] << 8);
            values[io::kFieldX + a] =
                as_float(inverse_log_transform(meta_.means_min[a] + meta_.means_range[a] * (step / kMeansSteps)));
            values[io::kFieldScale + a] =
                lookup(meta_.scales_codebook, t_.scales.rgba[o + a], "scales.codebook", meta_.scales, i);
            values[io::kFieldSh + a] = lookup(meta_.sh0_codebook, t_.sh0.rgba[o + a], "sh0.codebook", meta_.sh0, i);
        }
        const double opacity = std::clamp(t_.sh0.rgba[o + 3] / kByteSteps, kOpacityClamp, 1.0 - kOpacityClamp);
        values[io::kFieldOpacity] = as_float(std::log(opacity / (1.0 - opacity)));
        decode_quaternion(t_.quats.rgba.data() + o, i, values + io::kFieldRot);
        if (meta_.sh_degree > 0) decode_sh(o, i, values + io::kFieldSh + 3);
    }

private:
    double lookup(const std::vector<double>& codebook, unsigned char index, const char* key, const std::string& texture,
                  std::uint64_t i) const {
        if (index >= codebook.size())
            fail(path_,
                 "index " + std::to_string(index) + " is beyond the " + std::to_string(codebook.size()) +
                     "-entry codebook " + at_key(key),
                 files_.where(texture) + ", texel " + std::to_string(i));
        return codebook[index];
    }

    void decode_quaternion(const unsigned char* texel, std::uint64_t i, double* wxyz) const {
        const int tag = texel[3];
        if (tag < kQuatTagFirst)
            fail(path_, "quaternion tag " + std::to_string(tag) + " is not 252..255",
                 files_.where(meta_.quats) + ", texel " + std::to_string(i));
        const int largest = tag - kQuatTagFirst;
        double sum = 0.0;
        for (int c = 0, k = 0; c < 4; ++c) {
            if (c == largest) continue;
            const double v = (texel[k++] / kByteSteps * 2.0 - 1.0) / std::sqrt(2.0);
            wxyz[c] = as_float(v);
            sum += v * v;
        }
        wxyz[largest] = as_float(std::sqrt(std::max(0.0, 1.0 - sum)));
    }

    void decode_sh(std::size_t o, std::uint64_t i, double* rest) const {
        const std::uint64_t label = t_.labels.rgba[o] | (t_.labels.rgba[o + 1] << 8);
        if (label >= meta_.palette_entries)
            fail(path_,
                 "SH label " + std::to_string(label) + " is beyond the " + std::to_string(meta_.palette_entries) +
                     "-entry palette of " + at_key("shN.count"),
                 files_.where(meta_.labels) + ", texel " + std::to_string(i));
        const std::uint64_t coefficients = static_cast<std::uint64_t>(sh_coefficient_count(meta_.sh_degree)) - 1;
        const std::uint64_t first =
            (label / kPaletteColumns) * t_.centroids.width + (label % kPaletteColumns) * coefficients;
        for (std::uint64_t k = 0; k < coefficients; ++k)
            for (int c = 0; c < 3; ++c)
                rest[3 * k + c] = lookup(meta_.shn_codebook, t_.centroids.rgba[(first + k) * kRgba + c], "shN.codebook",
                                         meta_.centroids, first + k);
    }

    const std::string& path_;
    const SogMeta& meta_;
    const SogTextures& t_;
    const SogFiles& files_;
};

/// Refuses counts the stored bytes cannot plausibly hold, before any texture is decoded.
void check_count_against_size(const std::string& path, const SogMeta& m, SogFiles& files, std::uint64_t meta_bytes,
                              const LoadOptions& options) {
    io::check_limits(path, m.count, m.sh_degree, options);
    std::uint64_t stored = meta_bytes;
    const std::pair<const std::string*, const char*> textures[] = {{&m.means_l, "means.files[0]"},
                                                                   {&m.means_u, "means.files[1]"},
                                                                   {&m.quats, "quats.files[0]"},
                                                                   {&m.scales, "scales.files[0]"},
                                                                   {&m.sh0, "sh0.files[0]"}};
    for (const auto& [name, key] : textures) stored += files.stored_bytes(*name, key);
    if (m.count / kMaxGaussiansPerByte > stored)
        fail(path,
             "count " + std::to_string(m.count) + " is more than " + std::to_string(kMaxGaussiansPerByte) +
                 " Gaussians per byte of the " + std::to_string(stored) + " stored bytes",
             at_key("count"));
}

}  // namespace

Scene read_sog(const std::string& path, const LoadOptions& options, LoadReport* report) {
    std::uint64_t size = 0;
    FilePtr file = open_regular(path, path, "", size);
    if (size == 0) fail(path, "no Gaussians: the file is empty", io::at_offset(0));
    unsigned char magic[2] = {0, 0};
    const bool zip = std::fread(magic, 1, 2, file.get()) == 2 && magic[0] == 'P' && magic[1] == 'K';
    std::rewind(file.get());

    std::unique_ptr<SogFiles> files;
    std::vector<unsigned char> meta_bytes;
    if (zip) {
        files = sog::zip_files(path, file.release());
        meta_bytes = files->read(kMetaName, kMaxMetaBytes, "");
    } else {
        if (size > kMaxMetaBytes)
            fail(path, "file of " + std::to_string(size) + " bytes is neither a zip archive nor a SOG meta.json", "");
        meta_bytes = read_all(path, file.get(), size, "meta.json");
        file.reset();
        files = sog::directory_files(path, options.scene_root);
    }
    const SogMeta meta = read_meta(path, parse_json(path, meta_bytes));
    check_count_against_size(path, meta, *files, meta_bytes.size(), options);
    std::vector<unsigned char>().swap(meta_bytes);

    io::ProgressTicker ticker(options.progress, path);
    SogTextures textures = load_textures(path, *files, meta);
    io::SceneBuilder builder(path, meta.count, meta.sh_degree, kSogEncoding, sog_field_names(meta.sh_degree), options);
    const SogDecoder decoder(path, meta, textures, *files);
    constexpr std::uint64_t kRecordsPerTick = std::uint64_t{1} << 18;
    double values[io::kMaxFields];
    for (std::uint64_t i = 0; i < meta.count; ++i) {
        decoder.decode(i, values);
        builder.add(values, i);
        if ((i + 1) % kRecordsPerTick == 0) ticker.update(i + 1, meta.count);
    }
    // The textures go before the builder's last step, so the two are never both at their peak.
    textures = SogTextures{};
    Scene scene = builder.finish(report);
    ticker.finish();
    return scene;
}

}  // namespace catgs
