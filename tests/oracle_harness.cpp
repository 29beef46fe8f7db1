#include "oracle_harness.hpp"

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <random>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

extern char** environ;

namespace catgs::oracle {

namespace fs = std::filesystem;

namespace {

bool executable(const std::string& path) {
    return ::access(path.c_str(), X_OK) == 0;
}

/// splat-transform's bin is a node script (#!/usr/bin/env node): node must be on PATH.
bool node_on_path() {
    const char* path = std::getenv("PATH");
    std::stringstream dirs(path ? path : "");
    for (std::string dir; std::getline(dirs, dir, ':');)
        if (!dir.empty() && executable(dir + "/node")) return true;
    return false;
}

}  // namespace

std::string splat_transform(std::string* why) {
    std::string path;
    if (const char* env = std::getenv("CATGS_SPLAT_TRANSFORM")) {
        path = env;
    } else {
        path = std::string(CATGS_ORACLE_DIR) + "/node_modules/.bin/splat-transform";
    }
    std::string missing;
    if (!executable(path))
        missing = "splat-transform not found at " + path + " (run tests/oracle/install-deps.sh)";
    else if (!node_on_path())
        missing = "node is not on PATH, which splat-transform (" + path + ") needs";
    if (why) *why = missing;
    return missing.empty() ? path : "";
}

bool oracle_required() {
    const char* env = std::getenv("CATGS_REQUIRE_ORACLE");
    return env && std::string(env) == "1";
}

TempDir::TempDir(const std::string& name) {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    std::string test = info ? std::string(info->test_suite_name()) + "." + info->name() : "oracle";
    for (char& c : test)
        if (c == '/') c = '_';
    dir_ = std::string(CATGS_TEST_TMP) + "/oracle_" + test + "_" + name + "_" + std::to_string(::getpid());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
}

TempDir::~TempDir() {
    std::error_code ignored;
    fs::remove_all(dir_, ignored);
}

namespace {

/// A started splat-transform, its output going to a log file.
struct Child {
    pid_t pid = -1;
    std::string log;
    std::chrono::steady_clock::time_point start;
    std::string start_error;
};

Child spawn(const std::vector<std::string>& args) {
    static int sequence = 0;
    Child child;
    const std::string exe = splat_transform();
    if (exe.empty()) {
        child.start_error = "splat-transform is not installed";
        return child;
    }
    child.log = fs::temp_directory_path() /
                ("catgs-oracle-" + std::to_string(::getpid()) + "-" + std::to_string(sequence++) + ".log");
    std::vector<std::string> argv_strings = {exe};
    argv_strings.insert(argv_strings.end(), args.begin(), args.end());
    std::vector<char*> argv;
    for (std::string& a : argv_strings) argv.push_back(a.data());
    argv.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, child.log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_adddup2(&actions, STDOUT_FILENO, STDERR_FILENO);
    posix_spawn_file_actions_addopen(&actions, STDIN_FILENO, "/dev/null", O_RDONLY, 0);
    child.start = std::chrono::steady_clock::now();
    const int spawned = posix_spawn(&child.pid, exe.c_str(), &actions, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&actions);
    if (spawned != 0) {
        child.pid = -1;
        child.start_error = "cannot start " + exe + ": " + std::strerror(spawned);
    }
    return child;
}

RunResult finish(const Child& child, int status) {
    RunResult result;
    result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - child.start).count();
    if (WIFEXITED(status)) result.exit_status = WEXITSTATUS(status);
    std::ifstream in(child.log);
    result.output.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
    std::error_code ignored;
    fs::remove(child.log, ignored);
    return result;
}

int wait_for(pid_t pid) {
    int status = 0;
    while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
    }
    return status;
}

std::vector<std::string> arguments(const Conversion& c) {
    std::vector<std::string> args = {"-q", "-w"};
    args.insert(args.end(), c.flags.begin(), c.flags.end());
    args.push_back(c.in);
    args.push_back(c.out);
    return args;
}

bool check_result(const Conversion& c, const RunResult& run) {
    if (run.exit_status == 0 && fs::exists(c.out)) return true;
    ADD_FAILURE() << "splat-transform " << c.in << " -> " << c.out << " exited with " << run.exit_status << ":\n"
                  << run.output;
    return false;
}

}  // namespace

RunResult run_splat_transform(const std::vector<std::string>& args) {
    const Child child = spawn(args);
    if (child.pid < 0) return RunResult{-1, child.start_error, 0};
    return finish(child, wait_for(child.pid));
}

bool convert(const Conversion& conversion) {
    return check_result(conversion, run_splat_transform(arguments(conversion)));
}

bool convert_all(const std::vector<Conversion>& conversions) {
    bool ok = true;
    std::vector<std::pair<Child, std::size_t>> running;
    std::size_t next = 0;
    while (next < conversions.size() || !running.empty()) {
        while (next < conversions.size() && running.size() < kParallelConversions) {
            Child child = spawn(arguments(conversions[next]));
            if (child.pid < 0) {
                ok = check_result(conversions[next], RunResult{-1, child.start_error, 0}) && ok;
            } else {
                running.emplace_back(std::move(child), next);
            }
            ++next;
        }
        if (running.empty()) continue;
        int status = 0;
        pid_t done = -1;
        while ((done = ::waitpid(-1, &status, 0)) < 0 && errno == EINTR) {
        }
        for (auto it = running.begin(); it != running.end(); ++it)
            if (it->first.pid == done) {
                ok = check_result(conversions[it->second], finish(it->first, status)) && ok;
                running.erase(it);
                break;
            }
        if (done < 0) break;  // no children left that we know of: nothing more to wait for
    }
    return ok;
}

Scene asymmetric_scene(int sh_degree, std::size_t n, unsigned seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    Scene s;
    s.sh_degree = sh_degree;
    s.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
        s.positions[3 * i] = 1.0f + 2.0f * u(rng);
        s.positions[3 * i + 1] = -2.0f + 0.5f * u(rng);
        s.positions[3 * i + 2] = 4.0f + 3.0f * u(rng);
        for (int a = 0; a < 3; ++a) s.scales[3 * i + a] = std::exp(-4.0f + 2.0f * u(rng));
        float q[4], norm = 0;
        for (float& c : q) {
            c = u(rng) - 0.5f;
            norm += c * c;
        }
        for (int c = 0; c < 4; ++c) s.rotations[4 * i + c] = q[c] / std::sqrt(norm);
        s.opacities[i] = 0.1f + 0.85f * u(rng);
        for (std::size_t k = 0; k < s.sh_floats_per_gaussian(); ++k)
            s.sh[i * s.sh_floats_per_gaussian() + k] = (k < 3 ? 1.0f : 0.3f) * (u(rng) - 0.5f);
    }
    s.update_bounds();
    return s;
}

}  // namespace catgs::oracle
