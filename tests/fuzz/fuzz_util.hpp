// Helpers shared by the libFuzzer targets of tests/fuzz.
//
// Every target feeds untrusted bytes to one parser and checks what the parser promises:
// bad input ends in a catgs::Error (one line, naming the input) or a gRPC status, never in a
// crash, a sanitizer report, another exception type, a hang or unbounded memory. Good input
// must give results that hold the documented invariants. A broken promise aborts, which
// libFuzzer reports as a crash and saves the input.
#pragma once

#include <sys/mman.h>
#include <unistd.h>

#include <concepts>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <string_view>

namespace catgs::fuzz {

/// Inputs longer than this are ignored: every parser under test is linear in its input, and
/// larger inputs only slow the search down (libFuzzer's default -max_len is 4096 anyway).
inline constexpr std::size_t kMaxInputBytes = std::size_t{1} << 20;

/// The scene readers are capped at this many records (LoadOptions::max_records) so that no
/// input can make a target allocate more than a few tens of MB, far below libFuzzer's
/// -rss_limit_mb (2048 by default) and -malloc_limit_mb.
inline constexpr std::uint64_t kMaxRecords = 1u << 16;

[[noreturn]] inline void violation(const std::string& what) {
    std::fprintf(stderr, "catgs fuzz: broken promise: %s\n", what.c_str());
    std::fflush(stderr);
    std::abort();
}

inline void require(bool ok, const std::string& what) {
    if (!ok) violation(what);
}

/// A fixed message: no std::string is built unless the check fails.
inline void require(bool ok, const char* what) {
    if (!ok) violation(what);
}

/// A message built only when the check fails, for checks run per element: building a
/// std::string per check and element costs more, under ASan, than the parser under test.
template <std::invocable Message>
void require(bool ok, Message&& message) {
    if (!ok) violation(message());
}

/// The readers take a path. Each input is written to an in-memory file (memfd_create) that
/// is opened again through /proc/self/fd: no disk I/O per run, and parallel fuzz jobs never
/// share a file. The file is a regular file, as the readers require.
class MemoryFile {
public:
    MemoryFile() {
        fd_ = ::memfd_create("catgs-fuzz", MFD_CLOEXEC);
        if (fd_ < 0) {
            std::perror("memfd_create");
            std::abort();
        }
        path_ = "/proc/self/fd/" + std::to_string(fd_);
    }
    MemoryFile(const MemoryFile&) = delete;
    MemoryFile& operator=(const MemoryFile&) = delete;

    /// Replaces the file's contents; returns the path to open.
    const std::string& write(const std::uint8_t* data, std::size_t size) {
        if (::ftruncate(fd_, 0) != 0) std::abort();
        std::size_t done = 0;
        while (done < size) {
            const ssize_t n = ::pwrite(fd_, data + done, size - done, static_cast<off_t>(done));
            if (n <= 0) std::abort();
            done += static_cast<std::size_t>(n);
        }
        return path_;
    }

private:
    int fd_ = -1;
    std::string path_;
};

/// A catgs::Error message for a file is one line that starts with the path: "<path>: ..."
/// (scene_io.hpp, docs/formats.md, "Validation": one error line naming the file), or
/// "<path>:<line>: ..." for the line-oriented trajectory format.
inline void check_file_message(std::string_view message, const std::string& path) {
    require(message.substr(0, path.size() + 1) == path + ":",
            "error message does not start with the path: " + std::string(message));
    require(message.find('\n') == std::string_view::npos, "error message is not one line: " + std::string(message));
}

/// Any other message must still be one line and non-empty.
inline void check_one_line(std::string_view message) {
    require(!message.empty(), "empty error message");
    require(message.find('\n') == std::string_view::npos, "error message is not one line: " + std::string(message));
}

inline std::string as_string(const std::uint8_t* data, std::size_t size) {
    return std::string(reinterpret_cast<const char*>(data), size);
}

}  // namespace catgs::fuzz
