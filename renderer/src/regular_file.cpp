#include "catgs/regular_file.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

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

}  // namespace catgs
