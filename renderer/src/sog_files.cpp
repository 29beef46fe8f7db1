// The two sources of a SOG's textures (sog_files.hpp).
#include "sog_files.hpp"

#include <unistd.h>
#include <zip.h>

#include <cerrno>
#include <cstring>
#include <filesystem>

#include "catgs/regular_file.hpp"
#include "scene_io_detail.hpp"

namespace catgs::sog {
namespace {

using io::fail;
using io::quote;

struct ZipDeleter {
    void operator()(zip_t* archive) const { zip_discard(archive); }
    void operator()(zip_file_t* file) const { zip_fclose(file); }
};

class ZipFiles final : public SogFiles {
public:
    /// Takes ownership of `file`.
    ZipFiles(const std::string& path, std::FILE* file) : SogFiles(path) {
        zip_error_t error;
        zip_error_init(&error);
        zip_source_t* source = zip_source_filep_create(file, 0, -1, &error);
        if (!source) {
            std::fclose(file);
            fail_zip("cannot read the zip archive", error);
        }
        archive_.reset(zip_open_from_source(source, ZIP_RDONLY | ZIP_CHECKCONS, &error));
        if (!archive_) {
            zip_source_free(source);
            fail_zip("not a readable zip archive", error);
        }
        zip_error_fini(&error);
    }

    std::uint64_t stored_bytes(const std::string& name, const std::string& key) override {
        return stat(name, key).comp_size;
    }

    std::vector<unsigned char> read(const std::string& name, std::uint64_t max_bytes, const std::string& key) override {
        const zip_stat_t info = stat(name, key);
        if (info.size > max_bytes)
            fail(path_,
                 "zip entry " + quote(name) + " declares " + std::to_string(info.size) +
                     " uncompressed bytes, more than the " + std::to_string(max_bytes) + " that " + at_key(key) +
                     " can take",
                 where(name));
        std::unique_ptr<zip_file_t, ZipDeleter> file(zip_fopen_index(archive_.get(), info.index, 0));
        if (!file) fail(path_, "cannot open zip entry: " + std::string(zip_strerror(archive_.get())), where(name));
        std::vector<unsigned char> bytes(static_cast<std::size_t>(info.size));
        std::size_t done = 0;
        while (done < bytes.size()) {
            const zip_int64_t n = zip_fread(file.get(), bytes.data() + done, bytes.size() - done);
            if (n < 0) fail(path_, "corrupt zip entry: " + std::string(zip_file_strerror(file.get())), where(name));
            if (n == 0)
                fail(path_,
                     "zip entry ends after " + std::to_string(done) + " of its " + std::to_string(info.size) +
                         " declared bytes",
                     where(name));
            done += static_cast<std::size_t>(n);
        }
        // Reading on to the end makes libzip check the CRC, and catches a stream that inflates
        // to more than it declared.
        unsigned char extra = 0;
        const zip_int64_t n = zip_fread(file.get(), &extra, 1);
        if (n < 0) fail(path_, "corrupt zip entry: " + std::string(zip_file_strerror(file.get())), where(name));
        if (n > 0)
            fail(path_, "zip entry inflates to more than its declared " + std::to_string(info.size) + " bytes",
                 where(name));
        return bytes;
    }

    std::string where(const std::string& name) const override { return "zip entry " + quote(name); }

private:
    [[noreturn]] void fail_zip(const std::string& problem, zip_error_t& error) {
        const std::string message = zip_error_strerror(&error);
        zip_error_fini(&error);
        fail(path_, problem + ": " + message, "zip central directory");
    }

    zip_stat_t stat(const std::string& name, const std::string& key) {
        const zip_int64_t index = zip_name_locate(archive_.get(), name.c_str(), 0);
        if (index < 0) fail(path_, "zip entry " + quote(name) + " is missing", "named by " + at_key(key));
        zip_stat_t info;
        zip_stat_init(&info);
        if (zip_stat_index(archive_.get(), static_cast<zip_uint64_t>(index), 0, &info) != 0 ||
            (info.valid & (ZIP_STAT_SIZE | ZIP_STAT_COMP_SIZE | ZIP_STAT_INDEX)) !=
                (ZIP_STAT_SIZE | ZIP_STAT_COMP_SIZE | ZIP_STAT_INDEX))
            fail(path_, "cannot read the zip entry's size: " + std::string(zip_strerror(archive_.get())), where(name));
        return info;
    }

    std::unique_ptr<zip_t, ZipDeleter> archive_;
};

/// The textures of an unbundled meta.json: plain file names in the meta.json's directory.
class DirectoryFiles final : public SogFiles {
public:
    DirectoryFiles(const std::string& meta_path, std::string scene_root)
        : SogFiles(meta_path),
          directory_(std::filesystem::path(meta_path).parent_path()),
          scene_root_(std::move(scene_root)) {}

    std::uint64_t stored_bytes(const std::string& name, const std::string& key) override {
        std::uint64_t size = 0;
        open(name, key, size);
        return size;
    }

    std::vector<unsigned char> read(const std::string& name, std::uint64_t max_bytes, const std::string& key) override {
        std::uint64_t size = 0;
        FilePtr file = open(name, key, size);
        if (size > max_bytes)
            fail(path_,
                 "file holds " + std::to_string(size) + " bytes, more than the " + std::to_string(max_bytes) +
                     " that " + key + " can take",
                 where(name));
        return read_all(path_, file.get(), size, where(name));
    }

    std::string where(const std::string& name) const override { return "file " + quote(name) + " beside meta.json"; }

private:
    FilePtr open(const std::string& name, const std::string& key, std::uint64_t& size) {
        // Only names in the same directory: a meta.json must not reach other files.
        if (name.empty() || name == "." || name == ".." ||
            name.find_first_of(std::string("/\\\0", 3)) != std::string::npos)
            fail(path_, "texture name " + quote(name) + " is not a plain file name", at_key(key));
        const std::filesystem::path file = directory_ / name;
        // A missing file is left to open_regular, whose message says so.
        if (!scene_root_.empty() && std::filesystem::exists(file) && !resolves_within(scene_root_, file))
            fail(path_, "texture " + quote(name) + " resolves outside the scene root (a link?)", at_key(key));
        return open_regular(path_, file.string(), where(name), size);
    }

    std::filesystem::path directory_;
    std::string scene_root_;
};

}  // namespace

FilePtr open_regular(const std::string& path, const std::string& file, const std::string& where, std::uint64_t& size) {
    std::string problem;
    const int fd = open_regular_file(file, size, problem);
    if (fd < 0) fail(path, "cannot open: " + problem, where);
    FilePtr handle(::fdopen(fd, "rb"));
    if (!handle) {
        const int error = errno;
        ::close(fd);
        fail(path, "cannot open: " + std::string(std::strerror(error)), where);
    }
    return handle;
}

std::vector<unsigned char> read_all(const std::string& path, std::FILE* file, std::uint64_t size,
                                    const std::string& where) {
    std::vector<unsigned char> bytes(static_cast<std::size_t>(size));
    if (std::fread(bytes.data(), 1, bytes.size(), file) != bytes.size())
        fail(path, "read error: the file ends early or cannot be read", where);
    return bytes;
}

std::unique_ptr<SogFiles> zip_files(const std::string& path, std::FILE* file) {
    return std::make_unique<ZipFiles>(path, file);
}

std::unique_ptr<SogFiles> directory_files(const std::string& meta_path, const std::string& scene_root) {
    return std::make_unique<DirectoryFiles>(meta_path, scene_root);
}

}  // namespace catgs::sog
