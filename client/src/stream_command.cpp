// catgs-client stream: one session along a trajectory; the frames saved as they arrive, latency
// and fps each second, a summary line at the end.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "catgs/common/exit_codes.hpp"
#include "catgs/error.hpp"
#include "commands.hpp"
#include "exit_status.hpp"
#include "stop.hpp"

namespace catgs::client {
namespace {

const char* extension(v1::Encoding e) {
    return e == v1::ENCODING_PNG ? "png" : e == v1::ENCODING_RAW_RGB8 ? "rgb" : "jpg";
}

}  // namespace

CLI::App* add_stream_command(CLI::App& app, StreamArgs& args) {
    CLI::App* stream = app.add_subcommand("stream", "stream one trajectory, print latency and fps each second");
    add_session_flags(stream, args.session);
    stream->add_option("--out", args.out, "directory for the received frames (encoded bytes: .jpg, .png or .rgb)");
    stream->add_option("--max-frames", args.max_frames, "send at most this many poses");
    return stream;
}

int run_stream_command(const Connection& conn, const StreamArgs& args) {
    const SessionFlags& f = args.session;
    const std::string& out = args.out;
    const long max_frames = args.max_frames;
    Bounds bounds;
    if (grpc::Status s = scene_bounds(conn, f.scene, &bounds); !s.ok())
        return report_failure("GetScene '" + f.scene + "'", s);
    StreamPlan plan = make_plan(conn, f, bounds);
    if (max_frames > 0 && plan.poses > static_cast<std::size_t>(max_frames))
        plan.poses = static_cast<std::size_t>(max_frames);
    if (!out.empty()) {
        std::error_code ec;
        std::filesystem::create_directories(out, ec);
        if (ec) throw Error("--out '" + out + "': " + ec.message());
    }
    const std::string pace = f.rate > 0 ? std::to_string(static_cast<int>(std::lround(f.rate))) + " Hz" : "";
    std::printf("streaming %zu poses of %s at %s to %s (%dx%d %s)\n", plan.poses, f.trajectory.c_str(),
                f.rate <= 0   ? "lock step"
                : f.lock_step ? ("lock step, at most " + pace).c_str()
                              : pace.c_str(),
                conn.server.c_str(), f.width, f.height, f.encoding.c_str());
    std::fflush(stdout);
    // Per-second progress, from the reading thread.
    const Clock::time_point start = Clock::now();
    Clock::time_point window_start = start;
    LatencyRecorder window;
    std::uint64_t window_frames = 0, errors = 0;
    auto report = [&](Clock::time_point now) {
        const double secs = std::chrono::duration<double>(now - window_start).count();
        std::printf("t=%5.1fs  %5.1f fps  latency p50 %6.1f  p95 %6.1f  max %6.1f ms\n",
                    std::chrono::duration<double>(now - start).count(), secs > 0 ? window_frames / secs : 0.0,
                    window.percentile(0.5), window.percentile(0.95), window.max());
        std::fflush(stdout);
        window.clear();
        window_frames = 0;
        window_start = now;
    };
    auto on_frame = [&](const v1::Frame& frame, double latency) {
        if (frame.has_error()) {
            ++errors;
            std::fprintf(stderr, "frame %llu: error %d: %s\n", static_cast<unsigned long long>(frame.sequence()),
                         frame.error().code(), frame.error().message().c_str());
            return;
        }
        window.add(latency);
        ++window_frames;
        if (!out.empty()) {
            char name[64];
            std::snprintf(name, sizeof name, "frame_%05llu.%s", static_cast<unsigned long long>(frame.sequence()),
                          extension(frame.encoding()));
            std::ofstream file(std::filesystem::path(out) / name, std::ios::binary);
            file.write(frame.data().data(), static_cast<std::streamsize>(frame.data().size()));
        }
        const Clock::time_point now = Clock::now();
        if (now - window_start >= std::chrono::seconds(1)) report(now);
    };
    StreamResult r = run_stream_with_retries(conn.channel(), plan, on_frame, stop_requested(), conn.retry,
                                             [](const std::string& line) {
                                                 std::fprintf(stderr, "%s\n", line.c_str());
                                                 std::fflush(stderr);
                                             });
    if (window_frames > 0) report(Clock::now());
    const double secs = std::chrono::duration<double>(Clock::now() - start).count();
    std::printf(
        "summary: %llu poses sent, %llu frames (%.1f fps, %.2f MB), %llu poses coalesced by the server, %llu "
        "frame errors, %d reconnects; latency p50 %.1f p90 %.1f p99 %.1f max %.1f ms; first frame after %.1f ms; "
        "status %s%s%s\n",
        static_cast<unsigned long long>(r.poses_sent), static_cast<unsigned long long>(r.frames),
        secs > 0 ? r.frames / secs : 0.0, r.bytes / 1e6, static_cast<unsigned long long>(r.server_poses_coalesced),
        static_cast<unsigned long long>(r.frame_errors), r.reconnects, r.latency.percentile(0.5),
        r.latency.percentile(0.9), r.latency.percentile(0.99), r.latency.max(), r.time_to_first_frame_ms,
        code_name(r.status.error_code()), r.status.ok() ? "" : ": ", r.status.error_message().c_str());
    if (!r.status.ok()) return exit_code(r.status);
    return errors > 0 ? kExitFailure : kExitOk;
}

}  // namespace catgs::client
