// glTF 2.0 binary (.glb) with KHR_gaussian_splatting primitives, written from the glTF 2.0
// specification (GLB container, accessors) and the KHR_gaussian_splatting draft, checked
// against what splat-transform 3.7.0 writes. tinygltf parses the glTF; the container is
// checked here first, so that every malformed header gets a message that says where, and so
// that tinygltf only ever sees chunks that lie inside the file.
//
// Axes: glTF is LUF (+x left, +y up, +z forward); catgs keeps the PLY's RDF (x right, y down,
// z forward). The two differ by a half turn about z, its own inverse: x and y flip sign, the
// quaternion is premultiplied by (w, x, y, z) = (0, 0, 0, 1), and each SH coefficient of
// degree l and index c (m = c - l) is multiplied by (-1)^m, the half turn's action on it.

#include <sys/mman.h>
#include <tiny_gltf.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <map>
#include <string>
#include <vector>

#include "catgs/regular_file.hpp"
#include "catgs/scene_io.hpp"
#include "scene_io_detail.hpp"

namespace catgs {

namespace {

using io::fail;

constexpr std::uint32_t kGlbMagic = 0x46546C67;  ///< "glTF"
constexpr std::uint32_t kGlbVersion = 2;
constexpr std::uint32_t kJsonChunk = 0x4E4F534A;  ///< "JSON"
constexpr std::uint32_t kBinChunk = 0x004E4942;   ///< "BIN\0"
constexpr std::uint64_t kHeaderBytes = 12;
constexpr std::uint64_t kChunkHeaderBytes = 8;
/// glTF's JSON is a few objects deep (meshes[].primitives[].extensions.X); a hostile nesting
/// is refused before tinygltf's recursive parser sees it.
constexpr int kMaxJsonDepth = 64;
constexpr const char* kExtension = "KHR_gaussian_splatting";
constexpr const char* kPrefix = "KHR_gaussian_splatting:";

constexpr io::Encoding kGlbEncoding{
    .log_scale = false, .logit_opacity = false, .noun = "attribute", .nouns = "attributes"};

std::uint32_t le32(const unsigned char* p) {
    return io::load_scalar<std::uint32_t>(p, false);
}

/// The file, mapped read-only: tinygltf parses from memory, and the mapping costs no copy.
class MappedFile {
public:
    explicit MappedFile(const std::string& path) {
        std::string problem;
        fd_ = open_regular_file(path, size_, problem);
        if (fd_ < 0) fail(path, "cannot open: " + problem, "");
        if (size_ == 0) return;
        void* data = ::mmap(nullptr, size_, PROT_READ, MAP_PRIVATE, fd_, 0);
        if (data == MAP_FAILED) {
            const int error = errno;
            ::close(fd_);
            fail(path, "cannot map the file: " + std::string(std::strerror(error)), "");
        }
        data_ = static_cast<const unsigned char*>(data);
    }
    ~MappedFile() { release(); }
    MappedFile(const MappedFile&) = delete;
    MappedFile& operator=(const MappedFile&) = delete;

    void release() {
        if (data_) ::munmap(const_cast<unsigned char*>(data_), size_);
        if (fd_ >= 0) ::close(fd_);
        data_ = nullptr;
        fd_ = -1;
    }
    const unsigned char* data() const { return data_; }
    std::uint64_t size() const { return size_; }

private:
    int fd_ = -1;
    const unsigned char* data_ = nullptr;
    std::uint64_t size_ = 0;
};

/// Checks the GLB header and its JSON and BIN chunks (glTF 2.0, "Binary glTF Layout").
/// Returns the JSON chunk's offset and length.
std::pair<std::uint64_t, std::uint64_t> check_container(const std::string& path, const unsigned char* data,
                                                        std::uint64_t size) {
    if (size < kHeaderBytes)
        fail(path, "file of " + std::to_string(size) + " bytes is too short for the 12-byte GLB header",
             io::at_offset(0));
    if (le32(data) != kGlbMagic)
        fail(path, "not a GLB file: magic " + io::quote(std::string(reinterpret_cast<const char*>(data), 4)),
             io::at_offset(0));
    if (le32(data + 4) != kGlbVersion)
        fail(path, "GLB version " + std::to_string(le32(data + 4)) + "; expected 2", io::at_offset(4));
    const std::uint64_t length = le32(data + 8);
    if (length != size)
        fail(path,
             "the header declares " + std::to_string(length) + " bytes, the file holds " + std::to_string(size) +
                 (length > size ? ": the file is truncated" : ""),
             io::at_offset(8));
    if (length < kHeaderBytes + kChunkHeaderBytes)
        fail(path, "file ends inside the JSON chunk header", io::at_offset(12));
    const std::uint64_t json_length = le32(data + 12);
    if (le32(data + 16) != kJsonChunk) fail(path, "the first chunk is not JSON", io::at_offset(16));
    const std::uint64_t json_end = kHeaderBytes + kChunkHeaderBytes + json_length;
    if (json_length == 0 || json_end > length)
        fail(path, "JSON chunk of " + std::to_string(json_length) + " bytes runs past the end of the file",
             io::at_offset(12));
    if (json_end < length) {
        if (json_end + kChunkHeaderBytes > length)
            fail(path, "file ends inside the BIN chunk header", io::at_offset(json_end));
        const std::uint64_t bin_length = le32(data + json_end);
        if (le32(data + json_end + 4) != kBinChunk)
            fail(path, "the second chunk is not BIN", io::at_offset(json_end + 4));
        if (json_end + kChunkHeaderBytes + bin_length > length)
            fail(path, "BIN chunk of " + std::to_string(bin_length) + " bytes runs past the end of the file",
                 io::at_offset(json_end));
    }
    return {kHeaderBytes + kChunkHeaderBytes, json_length};
}

void check_json_depth(const std::string& path, const unsigned char* text, std::uint64_t length, std::uint64_t offset) {
    int depth = 0;
    bool in_string = false;
    for (std::uint64_t i = 0; i < length; ++i) {
        const unsigned char c = text[i];
        if (in_string) {
            if (c == '\\')
                ++i;
            else if (c == '"')
                in_string = false;
        } else if (c == '"') {
            in_string = true;
        } else if (c == '[' || c == '{') {
            if (++depth > kMaxJsonDepth)
                fail(path, "glTF JSON nests deeper than " + std::to_string(kMaxJsonDepth) + " levels",
                     io::at_offset(offset + i));
        } else if (c == ']' || c == '}') {
            --depth;
        }
    }
}

// tinygltf hooks: a .glb's splats are all in its BIN chunk; images are never decoded and no
// other file is ever read (a hostile file must not make the server open paths it names).
bool skip_image(tinygltf::Image*, const int, std::string*, std::string*, int, int, const unsigned char*, int, void*) {
    return true;
}
bool no_file_exists(const std::string&, void*) {
    return false;
}
std::string same_path(const std::string& path, void*) {
    return path;
}
bool refuse_read(std::vector<unsigned char>*, std::string* err, const std::string& file, void*) {
    if (err) *err += "external file " + file + " is not read: a .glb must hold its buffers";
    return false;
}
bool refuse_write(std::string*, const std::string&, const std::vector<unsigned char>&, void*) {
    return false;
}

/// tinygltf's error text, made one bounded line for a message.
std::string one_line(const std::string& text) {
    constexpr std::size_t kMaxShown = 300;
    std::string out;
    for (char c : text.substr(0, kMaxShown)) {
        const auto byte = static_cast<unsigned char>(c);
        if (c == '\n') {
            out += "; ";
        } else if (byte >= 0x20 && byte < 0x7f) {
            out += c;
        }
    }
    while (out.size() >= 2 && out.ends_with("; ")) out.resize(out.size() - 2);
    return out;
}

tinygltf::Model parse_gltf(const std::string& path, MappedFile& file) {
    const auto [json_offset, json_length] = check_container(path, file.data(), file.size());
    check_json_depth(path, file.data() + json_offset, json_length, json_offset);
    tinygltf::TinyGLTF loader;
    loader.SetImageLoader(skip_image, nullptr);
    loader.SetFsCallbacks({no_file_exists, same_path, refuse_read, refuse_write, nullptr});
    tinygltf::Model model;
    std::string error, warning;
    const bool ok =
        loader.LoadBinaryFromMemory(&model, &error, &warning, file.data(), static_cast<unsigned int>(file.size()), "");
    if (!ok) fail(path, "invalid glTF: " + one_line(error.empty() ? "tinygltf gave no reason" : error), "JSON chunk");
    return model;
}

// ---------------------------------------------------------------------------------------
// Accessors

/// One attribute of one primitive, checked against its buffer before any element is read.
class Attribute {
public:
    Attribute(const std::string& path, const tinygltf::Model& model, int index, const std::string& name, int components,
              std::uint64_t count) {
        const std::string where = "accessor " + std::to_string(index) + " ('" + name + "')";
        if (index < 0 || static_cast<std::size_t>(index) >= model.accessors.size())
            fail(path, "no such accessor", where);
        const tinygltf::Accessor& a = model.accessors[static_cast<std::size_t>(index)];
        if (a.sparse.isSparse) fail(path, "sparse accessors are not supported", where);
        if (tinygltf::GetNumComponentsInType(static_cast<std::uint32_t>(a.type)) != components)
            fail(path, "expected " + std::to_string(components) + " components per element", where);
        if (a.count != count)
            fail(path, "holds " + std::to_string(a.count) + " elements; POSITION has " + std::to_string(count), where);
        if (count == 0) return;
        type_ = a.componentType;
        const bool floating = type_ == TINYGLTF_COMPONENT_TYPE_FLOAT;
        const bool integer = type_ == TINYGLTF_COMPONENT_TYPE_BYTE || type_ == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE ||
                             type_ == TINYGLTF_COMPONENT_TYPE_SHORT || type_ == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT;
        if (!floating && !(integer && a.normalized))
            fail(path, "component type " + std::to_string(type_) + " is neither float nor a normalised integer", where);
        if (a.bufferView < 0 || static_cast<std::size_t>(a.bufferView) >= model.bufferViews.size())
            fail(path, "no such bufferView " + std::to_string(a.bufferView), where);
        const tinygltf::BufferView& view = model.bufferViews[static_cast<std::size_t>(a.bufferView)];
        if (view.buffer < 0 || static_cast<std::size_t>(view.buffer) >= model.buffers.size())
            fail(path, "bufferView " + std::to_string(a.bufferView) + " names no such buffer", where);
        const std::vector<unsigned char>& buffer = model.buffers[static_cast<std::size_t>(view.buffer)].data;
        component_bytes_ =
            static_cast<std::uint64_t>(tinygltf::GetComponentSizeInBytes(static_cast<std::uint32_t>(type_)));
        const std::uint64_t element = component_bytes_ * static_cast<std::uint64_t>(components);
        stride_ = view.byteStride != 0 ? view.byteStride : element;
        if (stride_ < element)
            fail(path, "byteStride " + std::to_string(stride_) + " is smaller than an element", where);
        // The last element must end inside both the bufferView and the buffer.
        std::uint64_t span = 0;
        if (!io::checked_mul(stride_, count - 1, span) || span > view.byteLength || a.byteOffset > view.byteLength ||
            view.byteLength - a.byteOffset < span + element || view.byteOffset > buffer.size() ||
            buffer.size() - view.byteOffset < view.byteLength)
            fail(path,
                 std::to_string(count) + " elements at byteOffset " + std::to_string(a.byteOffset) +
                     " run past bufferView " + std::to_string(a.bufferView) + " or its buffer",
                 where);
        data_ = buffer.data() + view.byteOffset + a.byteOffset;
        element_bytes_ = element;
    }

    std::uint64_t element_bytes() const { return element_bytes_; }

    /// Component c of element i, normalised integers mapped to [0, 1] or [-1, 1].
    double get(std::uint64_t i, int c) const {
        const unsigned char* p = data_ + i * stride_ + static_cast<std::uint64_t>(c) * component_bytes_;
        switch (type_) {
            case TINYGLTF_COMPONENT_TYPE_FLOAT:
                return io::load_scalar<float>(p, false);
            case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
                return p[0] / 255.0;
            case TINYGLTF_COMPONENT_TYPE_BYTE:
                return std::max(static_cast<std::int8_t>(p[0]) / 127.0, -1.0);
            case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
                return io::load_scalar<std::uint16_t>(p, false) / 65535.0;
            default:
                return std::max(io::load_scalar<std::int16_t>(p, false) / 32767.0, -1.0);
        }
    }

private:
    int type_ = 0;
    std::uint64_t component_bytes_ = 0, stride_ = 0, element_bytes_ = 0;
    const unsigned char* data_ = nullptr;
};

std::string sh_attribute(int degree, int coefficient) {
    return std::string(kPrefix) + "SH_DEGREE_" + std::to_string(degree) + "_COEF_" + std::to_string(coefficient);
}

bool is_splat_primitive(const tinygltf::Primitive& primitive) {
    return primitive.extensions.count(kExtension) > 0 ||
           primitive.attributes.count(std::string(kPrefix) + "ROTATION") > 0;
}

/// The SH degree a primitive carries: the highest degree whose coefficients are all there.
int primitive_sh_degree(const std::string& path, const tinygltf::Primitive& primitive, const std::string& where) {
    if (!primitive.attributes.count(sh_attribute(0, 0)))
        fail(path, "missing attribute " + io::quote(sh_attribute(0, 0)), where);
    int degree = 0;
    while (primitive.attributes.count(sh_attribute(degree + 1, 0))) {
        ++degree;
        if (degree > kMaxShDegree) fail(path, "SH degree " + std::to_string(degree) + " is beyond 3", where);
        for (int c = 0; c < 2 * degree + 1; ++c)
            if (!primitive.attributes.count(sh_attribute(degree, c)))
                fail(path, "SH degree " + std::to_string(degree) + " lacks " + io::quote(sh_attribute(degree, c)),
                     where);
    }
    return degree;
}

struct SplatPrimitive {
    const tinygltf::Primitive* primitive;
    std::string where;
    std::uint64_t count;
};

std::vector<SplatPrimitive> find_primitives(const std::string& path, const tinygltf::Model& model, int& sh_degree,
                                            std::uint64_t& total) {
    for (std::size_t n = 0; n < model.nodes.size(); ++n) {
        const tinygltf::Node& node = model.nodes[n];
        if (!node.matrix.empty() || !node.translation.empty() || !node.rotation.empty() || !node.scale.empty())
            fail(path, "node transforms are not supported: the splats are read in the file's own axes",
                 "node " + std::to_string(n));
    }
    std::vector<SplatPrimitive> found;
    total = 0;
    sh_degree = -1;
    for (std::size_t m = 0; m < model.meshes.size(); ++m)
        for (std::size_t p = 0; p < model.meshes[m].primitives.size(); ++p) {
            const tinygltf::Primitive& primitive = model.meshes[m].primitives[p];
            if (!is_splat_primitive(primitive)) continue;
            const std::string where = "mesh " + std::to_string(m) + ", primitive " + std::to_string(p);
            auto position = primitive.attributes.find("POSITION");
            if (position == primitive.attributes.end()) fail(path, "missing attribute 'POSITION'", where);
            if (position->second < 0 || static_cast<std::size_t>(position->second) >= model.accessors.size())
                fail(path, "no such accessor " + std::to_string(position->second), where + ", 'POSITION'");
            const std::uint64_t count = model.accessors[static_cast<std::size_t>(position->second)].count;
            const int degree = primitive_sh_degree(path, primitive, where);
            if (sh_degree >= 0 && degree != sh_degree)
                fail(path,
                     "SH degree " + std::to_string(degree) + " differs from the earlier primitives' " +
                         std::to_string(sh_degree),
                     where);
            sh_degree = degree;
            total += count;
            found.push_back({&primitive, where, count});
        }
    if (found.empty()) fail(path, "no mesh primitive carries KHR_gaussian_splatting attributes", "meshes");
    if (total == 0) fail(path, "no Gaussians: the splat primitives are empty", "meshes");
    return found;
}

std::vector<std::string> glb_field_names(int sh_degree) {
    std::vector<std::string> names = {"POSITION.x", "POSITION.y", "POSITION.z", "SCALE.x",    "SCALE.y",   "SCALE.z",
                                      "OPACITY",    "ROTATION.w", "ROTATION.x", "ROTATION.y", "ROTATION.z"};
    for (int l = 0; l <= sh_degree; ++l)
        for (int c = 0; c < 2 * l + 1; ++c)
            for (const char* channel : {".r", ".g", ".b"})
                names.push_back("SH_DEGREE_" + std::to_string(l) + "_COEF_" + std::to_string(c) + channel);
    return names;
}

/// A primitive's attributes, every one checked against its buffer.
struct PrimitiveAttributes {
    std::vector<Attribute> attributes;  ///< POSITION, ROTATION, SCALE, OPACITY, then the SH
    std::vector<double> sh_sign;
    std::uint64_t count;
};

/// The primitive that first used each accessor. The Gaussian count is the sum of the
/// primitives' counts, so primitives sharing an accessor of N elements would make the builder
/// allocate for N per primitive while the file holds the bytes of only N.
using AccessorOwners = std::map<int, std::string>;

void claim_accessor(const std::string& path, AccessorOwners& owners, int index, const std::string& name,
                    const std::string& where) {
    const auto [owner, fresh] = owners.try_emplace(index, where);
    if (!fresh && owner->second != where)
        fail(path, "reuses accessor " + std::to_string(index) + " ('" + name + "') of " + owner->second, where);
}

PrimitiveAttributes check_attributes(const std::string& path, const tinygltf::Model& model, const SplatPrimitive& splat,
                                     int sh_degree, AccessorOwners& owners) {
    PrimitiveAttributes checked{.attributes = {}, .sh_sign = {}, .count = splat.count};
    auto add = [&](const std::string& name, int components) {
        auto it = splat.primitive->attributes.find(name);
        if (it == splat.primitive->attributes.end()) fail(path, "missing attribute " + io::quote(name), splat.where);
        checked.attributes.emplace_back(path, model, it->second, name, components, splat.count);
        claim_accessor(path, owners, it->second, name, splat.where);
    };
    add("POSITION", 3);
    add(std::string(kPrefix) + "ROTATION", 4);
    add(std::string(kPrefix) + "SCALE", 3);
    add(std::string(kPrefix) + "OPACITY", 1);
    for (int l = 0; l <= sh_degree; ++l)
        for (int c = 0; c < 2 * l + 1; ++c) {
            add(sh_attribute(l, c), 3);
            checked.sh_sign.push_back((c + l) % 2 == 0 ? 1.0 : -1.0);  // (-1)^m, m = c - l
        }
    return checked;
}

/// Distinct accessors may still view the same bytes, which would multiply the count as a
/// shared accessor does. Each Gaussian's position needs bytes of its own in any real file, so
/// the positions together cannot need more bytes than the buffers hold.
void check_positions_fit(const std::string& path, const tinygltf::Model& model,
                         const std::vector<PrimitiveAttributes>& checked) {
    std::uint64_t held = 0, needed = 0;
    for (const tinygltf::Buffer& buffer : model.buffers) held += buffer.data.size();
    for (const PrimitiveAttributes& primitive : checked) {
        // Each term fits the buffers (the accessor was checked), so stopping at the first
        // excess keeps the sum far from overflowing.
        needed += primitive.count * primitive.attributes[0].element_bytes();
        if (needed > held)
            fail(path,
                 "the splat primitives' POSITION elements need more than the " + std::to_string(held) +
                     " bytes the buffers hold: primitives share their bytes",
                 "meshes");
    }
}

void read_primitive(const PrimitiveAttributes& checked, io::SceneBuilder& builder, std::uint64_t first_record) {
    const Attribute& position = checked.attributes[0];
    const Attribute& rotation = checked.attributes[1];
    const Attribute& scale = checked.attributes[2];
    const Attribute& opacity = checked.attributes[3];
    const Attribute* sh = checked.attributes.data() + 4;
    double values[io::kMaxFields];
    for (std::uint64_t i = 0; i < checked.count; ++i) {
        values[io::kFieldX + 0] = -position.get(i, 0);
        values[io::kFieldX + 1] = -position.get(i, 1);
        values[io::kFieldX + 2] = position.get(i, 2);
        for (int a = 0; a < 3; ++a) values[io::kFieldScale + a] = scale.get(i, a);
        // An opacity above 1 (a float accessor may hold one) saturates, as a renderer's blend would.
        values[io::kFieldOpacity] = std::min(opacity.get(i, 0), 1.0);
        // (0, 0, 0, 1) * (w, x, y, z) = (-z, -y, x, w); glTF stores (x, y, z, w).
        values[io::kFieldRot + 0] = -rotation.get(i, 2);
        values[io::kFieldRot + 1] = -rotation.get(i, 1);
        values[io::kFieldRot + 2] = rotation.get(i, 0);
        values[io::kFieldRot + 3] = rotation.get(i, 3);
        for (std::size_t k = 0; k < checked.sh_sign.size(); ++k)
            for (int c = 0; c < 3; ++c)
                values[io::kFieldSh + 3 * k + static_cast<std::size_t>(c)] = checked.sh_sign[k] * sh[k].get(i, c);
        builder.add(values, first_record + i);
    }
}

}  // namespace

Scene read_glb(const std::string& path, const LoadOptions& options, LoadReport* report) {
    MappedFile file(path);
    if (file.size() == 0) fail(path, "no Gaussians: the file is empty", io::at_offset(0));
    io::ProgressTicker ticker(options.progress, path);
    tinygltf::Model model = parse_gltf(path, file);
    // tinygltf holds its own copy of the BIN chunk; the mapping is not needed past here.
    file.release();

    int sh_degree = 0;
    std::uint64_t total = 0;
    // Every accessor is checked against its buffer, and the primitives against sharing
    // accessors or bytes, before the builder allocates for the counts they declare: a lying
    // count fails here, not in the allocation.
    std::vector<PrimitiveAttributes> checked;
    AccessorOwners owners;
    for (const SplatPrimitive& splat : find_primitives(path, model, sh_degree, total))
        checked.push_back(check_attributes(path, model, splat, sh_degree, owners));
    check_positions_fit(path, model, checked);
    io::SceneBuilder builder(path, total, sh_degree, kGlbEncoding, glb_field_names(sh_degree), options);
    std::uint64_t done = 0;
    for (const PrimitiveAttributes& primitive : checked) {
        read_primitive(primitive, builder, done);
        done += primitive.count;
        ticker.update(done, total);
    }
    model = tinygltf::Model{};
    Scene scene = builder.finish(report);
    ticker.finish();
    return scene;
}

}  // namespace catgs
