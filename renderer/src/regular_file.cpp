#include "catgs/regular_file.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <system_error>

namespace catgs {

int open_regular_file(const std::string& path, std::uint64_t& size, std::string& problem) {
    // O_NONBLOCK: opening a FIFO for reading would otherwise wait for a writer. It changes
    // nothing for a regular file, which is all that is kept.
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
    if (fd < 0) {
        problem = std::strerror(errno);
        return -1;
    }
    struct stat info {};
    if (::fstat(fd, &info) != 0) {
        problem = std::strerror(errno);
        ::close(fd);
        return -1;
    }
    if (!S_ISREG(info.st_mode)) {
        problem = "not a regular file";
        ::close(fd);
        return -1;
    }
    size = static_cast<std::uint64_t>(info.st_size);
    return fd;
}

std::optional<std::string> read_regular_file(const std::string& path, std::uint64_t max_bytes, std::string& problem) {
    std::uint64_t size = 0;
    const int fd = open_regular_file(path, size, problem);
    if (fd < 0) return std::nullopt;
    if (size > max_bytes) {
        problem = "the file holds " + std::to_string(size) + " bytes, more than the " + std::to_string(max_bytes) +
                  " accepted";
        ::close(fd);
        return std::nullopt;
    }
    std::string bytes(static_cast<std::size_t>(size), '\0');
    std::size_t done = 0;
    while (done < bytes.size()) {
        const ssize_t n = ::read(fd, bytes.data() + done, bytes.size() - done);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) {
            problem = n < 0 ? std::string(std::strerror(errno)) : "the file shrank while it was read";
            ::close(fd);
            return std::nullopt;
        }
        done += static_cast<std::size_t>(n);
    }
    ::close(fd);
    return bytes;
}

bool is_within(const std::filesystem::path& root, const std::filesystem::path& path) {
    const auto [root_end, path_at] = std::mismatch(root.begin(), root.end(), path.begin(), path.end());
    return root_end == root.end();
}

bool resolves_within(const std::filesystem::path& root, const std::filesystem::path& path) {
    std::error_code ec;
    const std::filesystem::path resolved_root = std::filesystem::canonical(root, ec);
    if (ec) return false;
    const std::filesystem::path resolved = std::filesystem::canonical(path, ec);
    return !ec && is_within(resolved_root, resolved);
}

}  // namespace catgs
