// catgs-client load: N open-loop sessions at once, as N separate viewers; a latency report
// over all of them, measured from each pose's intended send time.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <fstream>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "catgs/common/exit_codes.hpp"
#include "catgs/error.hpp"
#include "commands.hpp"
#include "exit_status.hpp"
#include "stop.hpp"

namespace catgs::client {
namespace {

/// The streams' results added up.
struct LoadTotals {
    LatencyRecorder latency, time_to_first_frame;
    std::map<std::string, int> codes;
    std::uint64_t poses = 0, frames = 0, errors = 0, bytes = 0, coalesced = 0, frames_coalesced = 0;
    int reconnects = 0;
};

/// `streams` copies of `plan`, each a viewer of its own, run at once; progress once a second.
/// `*streams_end` is when the last stream ended: the progress line's pending sleep must not
/// count in the run's wall time (it once added up to a second to it).
std::vector<StreamResult> run_streams(const Connection& conn, const StreamPlan& plan, int streams,
                                      Clock::time_point* streams_end) {
    std::vector<StreamResult> results(static_cast<std::size_t>(streams));
    std::atomic<std::uint64_t> frames_total{0};
    std::vector<std::thread> threads;
    const Clock::time_point start = Clock::now();
    for (int i = 0; i < streams; ++i) {
        threads.emplace_back([&, i] {
            StreamPlan mine = plan;
            // Stagger the streams along the path so they do not render identical frames.
            std::rotate(mine.path.begin(), mine.path.begin() + static_cast<long>((i * mine.path.size()) / streams),
                        mine.path.end());
            // One viewer per stream: each keeps its own server behind a proxy.
            mine.session_id = conn.session_id + "-" + std::to_string(i);
            RetryPolicy retry = conn.retry;
            if (retry.seed) retry.seed += static_cast<std::uint64_t>(i);
            results[static_cast<std::size_t>(i)] = run_stream_with_retries(
                conn.channel(true), mine,
                [&](const v1::Frame& frame, double) {
                    if (!frame.has_error()) ++frames_total;
                },
                stop_requested(), retry,
                [i](const std::string& line) { std::fprintf(stderr, "[stream %d] %s\n", i, line.c_str()); });
        });
    }
    std::mutex progress_mutex;
    std::condition_variable streams_done;
    bool done = false;
    std::thread progress([&] {
        std::uint64_t last = 0;
        for (Clock::time_point next = start + std::chrono::seconds(1);; next += std::chrono::seconds(1)) {
            {
                std::unique_lock lock(progress_mutex);
                if (streams_done.wait_until(lock, next, [&] { return done; })) break;
            }
            const std::uint64_t now = frames_total;
            std::fprintf(stderr, "t=%5.1fs  %llu frames/s over %d streams\n",
                         std::chrono::duration<double>(Clock::now() - start).count(),
                         static_cast<unsigned long long>(now - last), streams);
            last = now;
        }
    });
    for (auto& t : threads) t.join();
    *streams_end = Clock::now();
    {
        std::lock_guard lock(progress_mutex);
        done = true;
    }
    streams_done.notify_all();
    progress.join();
    return results;
}

LoadTotals add_up(const std::vector<StreamResult>& results) {
    LoadTotals t;
    for (const auto& r : results) {
        t.reconnects += r.reconnects;
        t.latency.merge(r.latency);
        if (r.time_to_first_frame_ms >= 0) t.time_to_first_frame.add(r.time_to_first_frame_ms);
        ++t.codes[code_name(r.status.error_code())];
        t.poses += r.poses_sent;
        t.frames += r.frames;
        t.errors += r.frame_errors;
        t.bytes += r.bytes;
        t.coalesced += r.server_poses_coalesced;
        t.frames_coalesced += r.server_frames_coalesced;
    }
    return t;
}

/// The run's two time bases. `elapsed` is the wall time from before the first connection to the
/// end of the last stream, each stream's setup and its last frames included; `schedule` is how
/// long the poses' open-loop schedule lasts (poses / rate: the last pose goes out one period
/// before its end). A server that answers every pose delivers streams x rate frames per second
/// of the schedule, whatever its setup costs; over `elapsed` only as much as the setup and the
/// last frame's latency take less than one pose period.
struct LoadTimes {
    double elapsed_s, schedule_s;
};

/// Frames received per pose sent: 1 when every pose got its frame, less by the poses the server
/// coalesced (latest wins) or that were still in flight when the run ended.
double served_fraction(const LoadTotals& t) {
    return t.poses > 0 ? static_cast<double>(t.frames) / static_cast<double>(t.poses) : 0.0;
}

nlohmann::json report_json(const Connection& conn, const SessionFlags& f, int streams, LoadTimes times,
                           const LoadTotals& t) {
    const LatencyRecorder& all = t.latency;
    const double elapsed = times.elapsed_s;
    return {{"server", conn.server},
            {"streams", streams},
            {"duration_s", elapsed},
            {"schedule_s", times.schedule_s},
            {"rate_hz", f.rate},
            {"width", f.width},
            {"height", f.height},
            {"encoding", f.encoding},
            {"poses_sent", t.poses},
            {"frames", t.frames},
            {"frames_per_s", t.frames / elapsed},
            {"frames_per_s_per_stream", t.frames / elapsed / streams},
            {"frames_per_s_of_schedule", t.frames / times.schedule_s},
            {"poses_served", served_fraction(t)},
            {"megabytes_per_s", t.bytes / elapsed / 1e6},
            {"poses_coalesced", t.coalesced},
            {"frames_coalesced", t.frames_coalesced},
            {"frame_errors", t.errors},
            {"reconnects", t.reconnects},
            {"latency_ms",
             {{"p50", all.percentile(0.5)},
              {"p90", all.percentile(0.9)},
              {"p95", all.percentile(0.95)},
              {"p99", all.percentile(0.99)},
              {"p99.9", all.percentile(0.999)},
              {"max", all.max()}}},
            {"time_to_first_frame_ms",
             {{"p50", t.time_to_first_frame.percentile(0.5)}, {"max", t.time_to_first_frame.max()}}},
            {"status_codes", t.codes}};
}

void print_report(const SessionFlags& f, int streams, LoadTimes times, const LoadTotals& t) {
    const LatencyRecorder& all = t.latency;
    const double elapsed = times.elapsed_s;
    std::printf("load: %d streams x %.1f s at %.0f Hz, %dx%d %s\n", streams, elapsed, f.rate, f.width, f.height,
                f.encoding.c_str());
    std::printf("  %-26s %12llu\n  %-26s %12llu\n  %-26s %12.1f\n  %-26s %12.2f\n  %-26s %12llu\n  %-26s %12llu\n",
                "poses sent", static_cast<unsigned long long>(t.poses), "frames received",
                static_cast<unsigned long long>(t.frames), "frames/s (all streams)", t.frames / elapsed, "MB/s",
                t.bytes / elapsed / 1e6, "poses coalesced (server)", static_cast<unsigned long long>(t.coalesced),
                "frame errors", static_cast<unsigned long long>(t.errors));
    std::printf("  %-26s %12d\n", "reconnects", t.reconnects);
    std::printf("  %-26s %12.1f   (%.1f s of poses; above: over all %.1f s, setup included)\n",
                "frames/s of the schedule", t.frames / times.schedule_s, times.schedule_s, elapsed);
    std::printf("  %-26s %12.1f%%\n", "poses served", 100.0 * served_fraction(t));
    std::printf("  latency ms (from intended send time)\n");
    for (const auto& [name, p] : std::vector<std::pair<std::string, double>>{
             {"p50", 0.5}, {"p90", 0.9}, {"p95", 0.95}, {"p99", 0.99}, {"p99.9", 0.999}})
        std::printf("    %-8s %10.1f\n", name.c_str(), all.percentile(p));
    std::printf("    %-8s %10.1f\n", "max", all.max());
    std::printf("  time to first frame ms     p50 %.1f  max %.1f\n", t.time_to_first_frame.percentile(0.5),
                t.time_to_first_frame.max());
    std::printf("  status codes:");
    for (const auto& [code, count] : t.codes) std::printf(" %s=%d", code.c_str(), count);
    std::printf("\n");
}

}  // namespace

CLI::App* add_load_command(CLI::App& app, LoadArgs& args) {
    CLI::App* load =
        app.add_subcommand("load", "N concurrent open-loop streams; latency percentiles and a JSON report");
    add_session_flags(load, args.session);
    load->add_option("--streams", args.streams, "concurrent streams")->capture_default_str();
    load->add_option("--duration", args.duration, "seconds")->capture_default_str();
    load->add_option("--json-out", args.json_out, "write the report as JSON to this file");
    return load;
}

int run_load_command(const Connection& conn, const LoadArgs& args) {
    const SessionFlags& f = args.session;
    if (args.streams < 1 || args.streams > 256) throw Error("--streams: expected 1..256");
    if (!(args.duration > 0 && args.duration <= 3600)) throw Error("--duration: expected (0, 3600] seconds");
    if (f.rate <= 0) throw Error("--rate: load runs open loop, give a positive pose rate");
    Bounds bounds;
    if (grpc::Status s = scene_bounds(conn, f.scene, &bounds); !s.ok())
        return report_failure("GetScene '" + f.scene + "'", s);
    StreamPlan plan = make_plan(conn, f, bounds);
    plan.poses = static_cast<std::size_t>(std::ceil(args.duration * f.rate));
    plan.max_duration = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(args.duration));

    const Clock::time_point start = Clock::now();
    Clock::time_point streams_end;
    const std::vector<StreamResult> results = run_streams(conn, plan, args.streams, &streams_end);
    const LoadTimes times{std::chrono::duration<double>(streams_end - start).count(),
                          static_cast<double>(plan.poses) / f.rate};

    const LoadTotals totals = add_up(results);
    print_report(f, args.streams, times, totals);
    if (!args.json_out.empty()) {
        std::ofstream file(args.json_out);
        if (!file) throw Error("--json-out '" + args.json_out + "': cannot write");
        file << report_json(conn, f, args.streams, times, totals).dump(2) << "\n";
    }
    for (const auto& r : results)
        if (!r.status.ok()) return exit_code(r.status);
    return kExitOk;
}

}  // namespace catgs::client
