// A fixed pool of worker threads with a FIFO task queue. Rendering and encoding run here,
// never on gRPC's threads: gRPC reactions must return quickly.
#pragma once

#include <condition_variable>
#include <deque>
#include <functional>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace catgs::server {

class WorkerPool {
public:
    WorkerPool(std::string name, int threads);
    ~WorkerPool();
    WorkerPool(const WorkerPool&) = delete;
    WorkerPool& operator=(const WorkerPool&) = delete;

    /// Queues a task; returns false (and drops it) once stop() has begun.
    bool post(std::function<void()> task);
    /// Runs the tasks already queued, then joins the threads. Idempotent.
    void stop();

private:
    void run();

    std::string name_;
    mutable std::mutex mutex_;  // a leaf, never held while a task runs (lock order: server_core.hpp)
    std::condition_variable wake_;
    std::deque<std::function<void()>> tasks_;
    bool stopping_ = false;
    std::vector<std::thread> threads_;
};

}  // namespace catgs::server
