// Child processes for the fault tests: catgs-server and catgs-client run as real binaries
// (so they can be killed), their stdout and stderr collected together.
#pragma once

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <memory>
#include <mutex>
#include <optional>
#include <random>
#include <string>
#include <thread>
#include <vector>

namespace catgs::test {

class Child {
public:
    /// Starts argv[0] with these arguments; stdout and stderr go to one pipe read by a thread.
    explicit Child(std::vector<std::string> argv) {
        int fds[2];
        // Close-on-exec: a child started meanwhile by another thread must not keep this pipe
        // open (its output would then never reach end of file). dup2 below clears the flag.
        if (pipe2(fds, O_CLOEXEC) != 0) return;
        pid_ = fork();
        if (pid_ == 0) {
            dup2(fds[1], STDOUT_FILENO);
            dup2(fds[1], STDERR_FILENO);
            close(fds[0]);
            close(fds[1]);
            std::vector<char*> args;
            for (auto& a : argv) args.push_back(a.data());
            args.push_back(nullptr);
            execv(args[0], args.data());
            _exit(127);
        }
        close(fds[1]);
        fd_ = fds[0];
        reader_ = std::thread([this] { read_all(); });
    }
    ~Child() {
        if (running()) {
            kill(SIGKILL);
            wait(std::chrono::seconds(10));
        }
        if (reader_.joinable()) reader_.join();
        if (fd_ >= 0) close(fd_);
    }
    Child(const Child&) = delete;
    Child& operator=(const Child&) = delete;

    pid_t pid() const { return pid_; }
    bool started() const { return pid_ > 0; }
    bool running() const { return pid_ > 0 && !status_; }
    void kill(int signal) const {
        if (running()) ::kill(pid_, signal);
    }
    /// Exit status (WEXITSTATUS, or 128 + signal), or nullopt when it is still running after
    /// `timeout`. Once it has exited, output() holds everything it wrote (the reader has
    /// drained the pipe; a process that inherited the pipe and lives on bounds the wait).
    std::optional<int> wait(std::chrono::milliseconds timeout) {
        if (status_) return status_;
        const auto end = std::chrono::steady_clock::now() + timeout;
        for (;;) {
            int w = 0;
            const pid_t r = waitpid(pid_, &w, WNOHANG);
            if (r == pid_) {
                status_ = WIFEXITED(w) ? WEXITSTATUS(w) : 128 + WTERMSIG(w);
                std::unique_lock lock(mutex_);
                drained_.wait_for(lock, std::chrono::seconds(5), [this] { return eof_; });
                return status_;
            }
            if (std::chrono::steady_clock::now() >= end) return std::nullopt;
            std::this_thread::sleep_for(std::chrono::milliseconds(10));
        }
    }
    std::string output() const {
        std::lock_guard lock(mutex_);
        return output_;
    }
    /// Waits until the output contains `needle`.
    bool wait_for_output(const std::string& needle, std::chrono::milliseconds timeout) const {
        const auto end = std::chrono::steady_clock::now() + timeout;
        while (std::chrono::steady_clock::now() < end) {
            if (output().find(needle) != std::string::npos) return true;
            std::this_thread::sleep_for(std::chrono::milliseconds(10));
        }
        return output().find(needle) != std::string::npos;
    }

private:
    void read_all() {
        char buffer[4096];
        for (;;) {
            const ssize_t n = read(fd_, buffer, sizeof buffer);
            if (n <= 0) break;
            std::lock_guard lock(mutex_);
            output_.append(buffer, static_cast<std::size_t>(n));
        }
        {
            std::lock_guard lock(mutex_);
            eof_ = true;
        }
        drained_.notify_all();
    }
    pid_t pid_ = -1;
    int fd_ = -1;
    std::optional<int> status_;
    std::thread reader_;
    mutable std::mutex mutex_;
    std::condition_variable drained_;
    bool eof_ = false;  // the reader saw the end of the pipe
    std::string output_;
};

/// Starts catgs-server (CATGS_SERVER_BINARY) with `args` and waits for its port line; 0 when
/// it did not start listening within `timeout`.
inline int wait_for_port(const Child& server, std::chrono::milliseconds timeout = std::chrono::milliseconds(30000)) {
    if (!server.wait_for_output("catgs-server: listening on port ", timeout)) return 0;
    const std::string out = server.output();
    int port = 0;
    std::sscanf(out.c_str() + out.find("catgs-server: listening on port "), "catgs-server: listening on port %d",
                &port);
    return port;
}

/// The seed for randomised tests: CATGS_TEST_SEED when set, else from the clock. Printed, so
/// that a failure can be replayed.
inline std::uint64_t test_seed(const char* test) {
    std::uint64_t seed = 0;
    if (const char* env = std::getenv("CATGS_TEST_SEED")) seed = std::strtoull(env, nullptr, 10);
    if (seed == 0) seed = static_cast<std::uint64_t>(std::chrono::steady_clock::now().time_since_epoch().count());
    std::printf("%s: seed %llu (replay with CATGS_TEST_SEED=%llu)\n", test, static_cast<unsigned long long>(seed),
                static_cast<unsigned long long>(seed));
    std::fflush(stdout);
    return seed;
}

}  // namespace catgs::test
