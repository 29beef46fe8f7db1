#include "catgs/server/worker_pool.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <limits>

namespace catgs::server {

WorkerPool::Flow& WorkerPool::Flow::operator=(Flow&& other) noexcept {
    if (this != &other) {
        close();
        pool_ = other.pool_;
        id_ = other.id_;
        other.pool_ = nullptr;
    }
    return *this;
}

void WorkerPool::Flow::close() {
    if (pool_) pool_->close_flow(id_);
    pool_ = nullptr;
}

WorkerPool::WorkerPool(std::string name, int threads) : name_(std::move(name)), thread_count_(std::max(threads, 1)) {
    for (int i = 0; i < thread_count_; ++i) threads_.emplace_back([this] { run(); });
}

WorkerPool::~WorkerPool() {
    stop();
}

WorkerPool::Flow WorkerPool::open_flow() {
    std::lock_guard lock(mutex_);
    return Flow(this, open_flow_locked());
}

std::uint64_t WorkerPool::open_flow_locked() {
    const std::uint64_t id = next_flow_id_++;
    flows_[id].virtual_time = virtual_time_;
    return id;
}

bool WorkerPool::post(std::function<void()> task) {
    bool posted = false;
    {
        std::lock_guard lock(mutex_);
        if (!stopping_) {
            const std::uint64_t id = open_flow_locked();
            flows_[id].closed = true;  // forgotten once its one task has run
            posted = post_locked(id, task);
        }
    }
    if (posted) wake_.notify_one();
    return posted;  // a refused task is destroyed here, outside the lock
}

bool WorkerPool::post(const Flow& flow, std::function<void()> task) {
    bool posted = false;
    {
        std::lock_guard lock(mutex_);
        if (!stopping_) posted = post_locked(flow.id_, task);
    }
    if (posted) wake_.notify_one();
    return posted;
}

bool WorkerPool::post_locked(std::uint64_t id, std::function<void()>& task) {
    auto it = flows_.find(id);
    if (it == flows_.end()) {
        // A closed flow already forgotten: its task still runs, as a one-off.
        it = flows_.emplace(id, FlowState{}).first;
        it->second.virtual_time = virtual_time_;
        it->second.closed = true;
    }
    FlowState& flow = it->second;
    if (flow.tasks.empty() && !flow.running) {
        // Ready again after being idle: no credit for the idle time (see the rule).
        flow.virtual_time = std::max(flow.virtual_time, virtual_time_);
        flow.ready_order = ++ready_counter_;
    }
    flow.tasks.push_back(std::move(task));
    ++queued_;
    return true;
}

void WorkerPool::close_flow(std::uint64_t id) {
    std::lock_guard lock(mutex_);
    auto it = flows_.find(id);
    if (it == flows_.end()) return;
    it->second.closed = true;
    forget_if_done_locked(it);
}

void WorkerPool::forget_if_done_locked(Flows::iterator it) {
    if (it->second.closed && !it->second.running && it->second.tasks.empty()) flows_.erase(it);
}

WorkerPool::Flows::iterator WorkerPool::pick_locked() {
    auto best = flows_.end();
    for (auto it = flows_.begin(); it != flows_.end(); ++it) {
        const FlowState& f = it->second;
        if (f.running || f.tasks.empty()) continue;
        if (best == flows_.end() || f.virtual_time < best->second.virtual_time ||
            (f.virtual_time == best->second.virtual_time && f.ready_order < best->second.ready_order))
            best = it;
    }
    return best;
}

void WorkerPool::advance_virtual_time_locked() {
    double least = std::numeric_limits<double>::infinity();
    for (const auto& [id, f] : flows_) {
        if (f.running)
            least = std::min(least, f.running_start);
        else if (!f.tasks.empty())
            least = std::min(least, f.virtual_time);
    }
    if (least != std::numeric_limits<double>::infinity()) virtual_time_ = std::max(virtual_time_, least);
}

void WorkerPool::stop() {
    {
        std::lock_guard lock(mutex_);
        if (stopping_ && threads_.empty()) return;
        stopping_ = true;
    }
    wake_.notify_all();
    for (auto& t : threads_)
        if (t.joinable()) t.join();
    threads_.clear();
}

void WorkerPool::run() {
    for (;;) {
        std::function<void()> task;
        std::uint64_t id = 0;
        {
            std::unique_lock lock(mutex_);
            Flows::iterator next = flows_.end();
            wake_.wait(lock, [&] {
                next = pick_locked();
                return next != flows_.end() || (stopping_ && queued_ == 0);
            });
            if (next == flows_.end()) return;  // stopping and drained
            FlowState& flow = next->second;
            task = std::move(flow.tasks.front());
            flow.tasks.pop_front();
            --queued_;
            flow.running = true;
            flow.running_start = flow.virtual_time;
            id = next->first;
            advance_virtual_time_locked();
        }
        const auto begin = std::chrono::steady_clock::now();
        try {
            task();
        } catch (const std::exception& e) {
            // Tasks handle their own errors; reaching here is a bug, but it must not kill the
            // server.
            spdlog::error("{} worker: task failed: {}", name_, e.what());
        }
        const double cost = std::chrono::duration<double>(std::chrono::steady_clock::now() - begin).count();
        // The task may hold the last reference to a session, whose Flow closes through
        // mutex_: it goes before the lock is taken.
        task = nullptr;
        bool ready_again = false, drained = false;
        {
            std::lock_guard lock(mutex_);
            if (auto it = flows_.find(id); it != flows_.end()) {
                FlowState& flow = it->second;
                flow.running = false;
                flow.virtual_time = flow.running_start + cost;
                ready_again = !flow.tasks.empty();
                if (ready_again) flow.ready_order = ++ready_counter_;
                forget_if_done_locked(it);
            }
            advance_virtual_time_locked();
            drained = stopping_ && queued_ == 0;
        }
        // Another worker may take the flow's next task; once drained, the idle ones exit.
        if (drained)
            wake_.notify_all();
        else if (ready_again)
            wake_.notify_one();
    }
}

}  // namespace catgs::server
