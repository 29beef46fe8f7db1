// Files read whole (trajectories, cameras.json, tokens, certificates, sweeps) and the opening
// of scene files: only regular files, opened without blocking, and bounded in size. A FIFO
// would block the open until a writer came, and /dev/zero named as a trajectory would be read
// into memory without end; both are refused, by name, before anything is read.
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>

namespace catgs {

/// Trajectories and cameras.json: ten hours of poses at 60 Hz take about 260 MB.
inline constexpr std::uint64_t kMaxCameraFileBytes = std::uint64_t{1} << 30;
/// Bearer tokens, PEM certificates and keys, --sweep files: a few KB in use.
inline constexpr std::uint64_t kMaxSmallFileBytes = std::uint64_t{16} << 20;

/// Opens `path` read-only and close-on-exec without blocking, and checks that it is a regular
/// file. Returns the descriptor with its size, or -1 with `problem` set to why not
/// ("No such file or directory", "not a regular file", ...).
int open_regular_file(const std::string& path, std::uint64_t& size, std::string& problem);

/// The whole of the regular file at `path` if it holds at most `max_bytes`; otherwise nullopt
/// with `problem` set to why.
std::optional<std::string> read_regular_file(const std::string& path, std::uint64_t max_bytes, std::string& problem);

/// Whether `path` lies inside the directory `root`, both already resolved
/// (std::filesystem::canonical), compared component by component: /a/bc is not inside /a/b.
bool is_within(const std::filesystem::path& root, const std::filesystem::path& path);

/// Whether `path` lies inside the directory `root` once both are resolved (links, "." and ".."
/// followed); false when either cannot be resolved.
bool resolves_within(const std::filesystem::path& root, const std::filesystem::path& path);

}  // namespace catgs
