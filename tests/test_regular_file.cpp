// Files that catgs reads whole or opens by name (catgs/regular_file.hpp): a FIFO, a device or a
// directory is refused by name before anything is read, and without blocking (a FIFO nobody
// writes to would otherwise hang the open); a file over its bound is refused before it is read.
// Every reader of such files goes through it: scene files, trajectories, cameras.json, and the
// files that flags name (tokens, certificates, --sweep).

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <vector>

#include "catgs/common/files.hpp"
#include "catgs/error.hpp"
#include "catgs/regular_file.hpp"
#include "catgs/scene_io.hpp"
#include "catgs/trajectory.hpp"

namespace catgs {
namespace {

namespace fs = std::filesystem;

struct TempDirectory {
    fs::path path;
    explicit TempDirectory(const std::string& name) : path(fs::path(CATGS_TEST_TMP) / name) {
        fs::remove_all(path);
        fs::create_directories(path);
    }
    ~TempDirectory() {
        std::error_code ignored;
        fs::remove_all(path, ignored);
    }
};

/// The message `read` throws, or "" when it throws nothing.
std::string error_of(const std::function<void()>& read) {
    try {
        read();
    } catch (const Error& e) {
        return e.what();
    }
    return "";
}

TEST(RegularFile, ReadsARegularFileWhole) {
    const TempDirectory dir("regular_file_whole");
    const std::string path = (dir.path / "bytes.bin").string();
    const std::string bytes("first line\r\nsecond\0third", 24);
    std::ofstream(path, std::ios::binary) << bytes;
    std::string problem;
    const std::optional<std::string> read = read_regular_file(path, bytes.size(), problem);
    ASSERT_TRUE(read) << problem;
    EXPECT_EQ(*read, bytes);
    EXPECT_EQ(read_token(path), "first line");
}

TEST(RegularFile, ContainmentComparesWholeComponentsAfterFollowingLinks) {
    EXPECT_TRUE(is_within("/a/b", "/a/b"));
    EXPECT_TRUE(is_within("/a/b", "/a/b/c/d"));
    EXPECT_TRUE(is_within("/", "/a"));
    EXPECT_FALSE(is_within("/a/b", "/a/bc"));  // a prefix of the text, not of the path
    EXPECT_FALSE(is_within("/a/b", "/a"));

    const TempDirectory dir("regular_file_within");
    const fs::path root = dir.path / "root", outside = dir.path / "outside";
    fs::create_directories(root / "sub");
    fs::create_directories(outside);
    std::ofstream(root / "sub" / "in.bin") << "in";
    std::ofstream(outside / "out.bin") << "out";
    fs::create_symlink(outside / "out.bin", root / "out-link.bin");
    fs::create_symlink(root / "sub" / "in.bin", root / "in-link.bin");
    EXPECT_TRUE(resolves_within(root, root / "sub" / "in.bin"));
    EXPECT_TRUE(resolves_within(root, root / "in-link.bin"));
    EXPECT_TRUE(resolves_within(root, root / "sub" / ".." / "sub" / "in.bin"));
    EXPECT_FALSE(resolves_within(root, root / "out-link.bin"));
    EXPECT_FALSE(resolves_within(root, root / ".." / "outside" / "out.bin"));
    EXPECT_FALSE(resolves_within(root, root / "missing.bin"));  // cannot be resolved
}

TEST(RegularFile, AFileOverItsBoundIsRefusedWithItsSize) {
    const TempDirectory dir("regular_file_bound");
    const std::string path = (dir.path / "big.txt").string();
    std::ofstream(path) << std::string(1000, 'x');
    std::string problem;
    EXPECT_FALSE(read_regular_file(path, 999, problem));
    EXPECT_EQ(problem, "the file holds 1000 bytes, more than the 999 accepted");
    EXPECT_TRUE(read_regular_file(path, 1000, problem));
}

TEST(RegularFile, FifosDevicesAndDirectoriesAreRefusedByEveryReader) {
    const TempDirectory dir("regular_file_kinds");
    const std::string fifo = (dir.path / "scene.ply").string();
    ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
    const std::vector<std::string> not_regular = {fifo, "/dev/zero", dir.path.string()};
    for (const std::string& path : not_regular) {
        SCOPED_TRACE(path);
        std::uint64_t size = 0;
        std::string problem;
        EXPECT_EQ(open_regular_file(path, size, problem), -1);
        EXPECT_EQ(problem, "not a regular file");
        EXPECT_EQ(error_of([&] { load_scene(path); }), path + ": cannot open: not a regular file");
        EXPECT_EQ(error_of([&] { read_trajectory(path, intrinsics_from_fov(64, 48, 60)); }),
                  path + ": cannot open trajectory file: not a regular file");
        EXPECT_EQ(error_of([&] { read_cameras_json(path); }), path + ": cannot open cameras file: not a regular file");
        EXPECT_EQ(error_of([&] { read_file(path, "--tls-cert"); }),
                  "--tls-cert '" + path + "': cannot read the file: not a regular file");
        EXPECT_EQ(error_of([&] { read_token(path); }),
                  "--token-file '" + path + "': cannot read the file: not a regular file");
    }
}

TEST(RegularFile, AMissingFileIsNamedWithTheSystemsReason) {
    const TempDirectory dir("regular_file_missing");
    const std::string path = (dir.path / "missing.txt").string();
    EXPECT_EQ(error_of([&] { read_trajectory(path, intrinsics_from_fov(64, 48, 60)); }),
              path + ": cannot open trajectory file: No such file or directory");
    EXPECT_EQ(error_of([&] { read_token(path); }),
              "--token-file '" + path + "': cannot read the file: No such file or directory");
}

}  // namespace
}  // namespace catgs
