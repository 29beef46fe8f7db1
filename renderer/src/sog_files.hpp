// Where a SOG's textures come from: the zip of a .sog, or the directory of an unbundled
// meta.json (sog_reader.cpp reads the format itself). Every read is bounded before anything is
// inflated or read, and every failure names the file and the entry.
#pragma once

#include <cstdint>
#include <cstdio>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace catgs::sog {

/// Where a meta.json key is; the empty key is meta.json itself, which every SOG holds.
inline std::string at_key(const std::string& key) {
    if (key.empty()) return "the SOG format";
    return "meta.json '" + key + "'";
}

/// The files of one SOG, read by name.
class SogFiles {
public:
    explicit SogFiles(std::string path) : path_(std::move(path)) {}
    virtual ~SogFiles() = default;
    SogFiles(const SogFiles&) = delete;
    SogFiles& operator=(const SogFiles&) = delete;

    /// The stored (compressed) size of `name`, for the bound on the count.
    virtual std::uint64_t stored_bytes(const std::string& name, const std::string& key) = 0;
    /// The bytes of `name`, refused before anything is inflated or read when it declares
    /// more than max_bytes. `key` is the meta.json key that named it.
    virtual std::vector<unsigned char> read(const std::string& name, std::uint64_t max_bytes,
                                            const std::string& key) = 0;
    virtual std::string where(const std::string& name) const = 0;

protected:
    std::string path_;
};

struct FileCloser {
    void operator()(std::FILE* file) const { std::fclose(file); }
};
using FilePtr = std::unique_ptr<std::FILE, FileCloser>;

/// Opens a regular file for reading, with its size; `where` names it in messages.
FilePtr open_regular(const std::string& path, const std::string& file, const std::string& where, std::uint64_t& size);
/// All `size` bytes of `file`.
std::vector<unsigned char> read_all(const std::string& path, std::FILE* file, std::uint64_t size,
                                    const std::string& where);

/// The entries of the zip archive `file` (taken over) of the .sog at `path`.
std::unique_ptr<SogFiles> zip_files(const std::string& path, std::FILE* file);
/// The textures beside the unbundled meta.json at `meta_path`, each refused unless it resolves
/// inside `scene_root` (LoadOptions::scene_root; empty: not checked).
std::unique_ptr<SogFiles> directory_files(const std::string& meta_path, const std::string& scene_root);

}  // namespace catgs::sog
