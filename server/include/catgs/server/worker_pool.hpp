// A fixed pool of worker threads shared fairly between flows (sessions). Rendering and
// encoding run here, never on gRPC's threads: gRPC reactions must return quickly.
//
// The rule (start-time fair queueing over the pool, by measured cost):
// - Each flow (one per session and pool) has a virtual time: the worker seconds its tasks
//   have taken so far. A task's cost is measured, not estimated: the wall time it held a
//   worker, which for a render is what its pixels cost at that view of the scene, so a 1080p
//   render is charged about 27 times a 320x240 one.
// - A free worker takes the head task of the ready flow with the least virtual time (ties: the
//   flow that became ready first). A flow runs at most one task at a time, and its tasks run in
//   the order posted; a session queues at most one render, so it holds at most one worker.
// - The pool's virtual time V is the least start time among the tasks running and the flows
//   waiting, never decreasing. A flow that becomes ready after being idle (a new session, a
//   viewer whose next pose arrives) starts at max(its own time, V): it goes ahead of the
//   flows that have taken more than their share, and an idle flow banks no credit to burst
//   with later.
// - Tasks posted without a flow (scene loads, unary renders) are one-task flows entering at V.
// So a small viewer's render waits at most for the tasks already running, never behind the
// backlog of a large or greedy one; when nobody else is waiting, a greedy flow takes the
// whole pool (the scheduler never idles a worker).
#pragma once

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <mutex>
#include <string>
#include <thread>
#include <unordered_map>
#include <vector>

namespace catgs::server {

class WorkerPool {
public:
    WorkerPool(std::string name, int threads);
    ~WorkerPool();
    WorkerPool(const WorkerPool&) = delete;
    WorkerPool& operator=(const WorkerPool&) = delete;

    /// A flow's handle: its tasks are scheduled as one (see the rule above). Closing it (the
    /// destructor) lets the pool forget the flow once its queued tasks have run.
    class Flow {
    public:
        Flow() = default;
        Flow(Flow&& other) noexcept : pool_(other.pool_), id_(other.id_) { other.pool_ = nullptr; }
        Flow& operator=(Flow&& other) noexcept;
        Flow(const Flow&) = delete;
        Flow& operator=(const Flow&) = delete;
        ~Flow() { close(); }

    private:
        friend class WorkerPool;
        Flow(WorkerPool* pool, std::uint64_t id) : pool_(pool), id_(id) {}
        void close();
        WorkerPool* pool_ = nullptr;
        std::uint64_t id_ = 0;
    };

    /// A new flow; it enters at the pool's current virtual time with its first task.
    Flow open_flow();
    /// Queues a one-task flow; returns false (and drops the task) once stop() has begun.
    bool post(std::function<void()> task);
    /// Queues `task` behind `flow`'s earlier tasks; the same result.
    bool post(const Flow& flow, std::function<void()> task);
    /// Runs the tasks already queued, then joins the threads. Idempotent.
    void stop();
    int threads() const { return thread_count_; }

private:
    struct FlowState {
        double virtual_time = 0;  ///< worker seconds charged so far (see the rule above)
        std::deque<std::function<void()>> tasks;
        bool running = false;           ///< one of its tasks holds a worker
        double running_start = 0;       ///< the virtual time its running task started at
        std::uint64_t ready_order = 0;  ///< when it last became ready: breaks ties
        bool closed = false;            ///< forgotten once idle with nothing queued
    };
    using Flows = std::unordered_map<std::uint64_t, FlowState>;

    void run();
    std::uint64_t open_flow_locked();
    bool post_locked(std::uint64_t id, std::function<void()>& task);
    void close_flow(std::uint64_t id);
    /// The ready flow (queued work, none running) with the least virtual time, or end().
    /// Linear: flows are bounded by the admitted sessions plus queued one-off tasks.
    Flows::iterator pick_locked();
    void advance_virtual_time_locked();
    void forget_if_done_locked(Flows::iterator it);

    std::string name_;
    const int thread_count_;
    // A leaf, never held while a task runs nor while a task is destroyed (a task may hold the
    // last reference to a session, whose Flow closes through this lock). Lock order:
    // server_core.hpp.
    mutable std::mutex mutex_;
    std::condition_variable wake_;
    Flows flows_;
    std::uint64_t next_flow_id_ = 1;
    std::uint64_t ready_counter_ = 0;
    std::size_t queued_ = 0;   ///< tasks queued in all flows, not yet running
    double virtual_time_ = 0;  ///< V of the rule above
    bool stopping_ = false;
    std::vector<std::thread> threads_;
};

}  // namespace catgs::server
