// catgs-client: talks to catgs-server.
//   stream  one session along a trajectory; saves frames, prints latency and fps per second
//   load    N concurrent open-loop sessions for a duration; latency percentiles, JSON report
//   scenes  list | get ID | load SOURCE | unload ID
// Exit status: 0 success; 1 the RPC failed otherwise; 2 bad input (one line on stderr);
// 3 server unreachable or shutting down (UNAVAILABLE after --retries reconnections,
// DEADLINE_EXCEEDED); 4 refused by a server limit (RESOURCE_EXHAUSTED); 5 not authenticated
// (UNAUTHENTICATED, PERMISSION_DENIED);
// 6 the server rejected the request (INVALID_ARGUMENT, NOT_FOUND, FAILED_PRECONDITION,
// ALREADY_EXISTS).
#include <CLI/CLI.hpp>
#include <grpcpp/grpcpp.h>

#include <cmath>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <nlohmann/json.hpp>
#include <random>
#include <sstream>
#include <thread>

#include "catgs/error.hpp"
#include "catgs/render_options.hpp"
#include "catgs/server/net_config.hpp"
#include "catgs/trajectory.hpp"
#include "stream_runner.hpp"

namespace {

using namespace catgs;
using client::Clock;

constexpr int kExitOk = 0, kExitFailure = 1, kExitBadInput = 2, kExitUnavailable = 3, kExitLimit = 4,
              kExitUnauthenticated = 5, kExitRejected = 6;
/// How long to wait for the first connection before giving up with kExitUnavailable.
constexpr auto kConnectTimeout = std::chrono::seconds(10);

int exit_code(const grpc::Status& s) {
    switch (s.error_code()) {
    case grpc::StatusCode::OK: return kExitOk;
    case grpc::StatusCode::UNAVAILABLE:
    case grpc::StatusCode::DEADLINE_EXCEEDED: return kExitUnavailable;
    case grpc::StatusCode::RESOURCE_EXHAUSTED: return kExitLimit;
    case grpc::StatusCode::UNAUTHENTICATED:
    case grpc::StatusCode::PERMISSION_DENIED: return kExitUnauthenticated;
    case grpc::StatusCode::INVALID_ARGUMENT:
    case grpc::StatusCode::NOT_FOUND:
    case grpc::StatusCode::FAILED_PRECONDITION:
    case grpc::StatusCode::ALREADY_EXISTS: return kExitRejected;
    default: return kExitFailure;
    }
}

const char* code_name(grpc::StatusCode code) {
    static const char* names[] = {"OK", "CANCELLED", "UNKNOWN", "INVALID_ARGUMENT", "DEADLINE_EXCEEDED", "NOT_FOUND",
                                  "ALREADY_EXISTS", "PERMISSION_DENIED", "RESOURCE_EXHAUSTED", "FAILED_PRECONDITION",
                                  "ABORTED", "OUT_OF_RANGE", "UNIMPLEMENTED", "INTERNAL", "UNAVAILABLE", "DATA_LOSS",
                                  "UNAUTHENTICATED"};
    const int i = static_cast<int>(code);
    return i >= 0 && i < 17 ? names[i] : "?";
}

std::atomic<bool> g_stop{false};
void on_signal(int) { g_stop = true; }

std::string read_file(const std::string& path, const std::string& flag) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw Error(flag + " '" + path + "': cannot read the file");
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
}

struct Connection {
    std::string server = "localhost:50051";
    std::string token_file;
    std::string tls_ca;  ///< PEM CA: use TLS
    std::string tls_cert, tls_key;  ///< PEM client certificate and key (mTLS)
    bool tls = false;
    client::RetryPolicy retry;
    /// Sent as metadata x-catgs-session on every call: a front proxy (deploy/envoy*.yaml)
    /// routes calls with the same value to the same server, so a reconnecting viewer finds its
    /// scene warm there. Empty: a random id per run.
    std::string session_id;

    /// Adds the metadata every call carries: the bearer token and the session id.
    void add_metadata(grpc::ClientContext& context, const std::string& authorization) const {
        if (!authorization.empty()) context.AddMetadata("authorization", authorization);
        if (!session_id.empty()) context.AddMetadata(client::kSessionHeader, session_id);
    }

    std::string authorization() const {
        if (token_file.empty()) return "";
        std::ifstream in(token_file);
        std::string token;
        if (!in || !std::getline(in, token) || token.empty())
            throw Error("--token-file '" + token_file + "': cannot read a token from its first line");
        return "Bearer " + token;
    }
    std::shared_ptr<grpc::Channel> channel(bool own_connection = false) const {
        std::shared_ptr<grpc::ChannelCredentials> creds = grpc::InsecureChannelCredentials();
        if (tls_cert.empty() != tls_key.empty()) throw Error("--tls-cert and --tls-key: give both or neither");
        if (tls || !tls_ca.empty() || !tls_cert.empty()) {
            grpc::SslCredentialsOptions ssl;
            if (!tls_ca.empty()) ssl.pem_root_certs = read_file(tls_ca, "--tls-ca");
            if (!tls_cert.empty()) {
                ssl.pem_cert_chain = read_file(tls_cert, "--tls-cert");
                ssl.pem_private_key = read_file(tls_key, "--tls-key");
            }
            creds = grpc::SslCredentials(ssl);
        }
        grpc::ChannelArguments args = net::client_channel_args();
        // The channel's own reconnection follows our backoff, so a restarted server is found
        // as soon as a retry asks for it.
        args.SetInt(GRPC_ARG_INITIAL_RECONNECT_BACKOFF_MS, static_cast<int>(retry.backoff.count()));
        args.SetInt(GRPC_ARG_MIN_RECONNECT_BACKOFF_MS, static_cast<int>(retry.backoff.count()));
        args.SetInt(GRPC_ARG_MAX_RECONNECT_BACKOFF_MS, static_cast<int>(retry.max_backoff.count()));
        // Load tests: one TCP connection per stream, as separate viewers would have.
        if (own_connection) args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
        return grpc::CreateCustomChannel(server, creds, args);
    }
};

struct SessionFlags {
    std::string scene = "city";
    std::string trajectory = "builtin:survey";
    int width = 960, height = 540;
    double fov = 70;
    std::string encoding = "jpeg";
    int quality = 85;
    // "server": leave the field unset, so the server's default applies (README, defaults).
    std::string cache = "server";
    std::string window = "adaptive";
    std::string split = "server";
    std::string resort = "server";
    std::string reuse_order_max_deg = "server";
    int max_unacked = 2;
    int flight_plan = 0;
    bool no_velocity = false;
    double rate = 30;
    bool lock_step = false;
};

void add_session_flags(CLI::App* app, SessionFlags& f) {
    app->add_option("--scene", f.scene, "scene id on the server")->capture_default_str();
    app->add_option("--trajectory", f.trajectory,
                    "trajectory file or builtin:survey|orbit|flythrough|hover?... laid over the scene's bounds")
        ->capture_default_str();
    app->add_option("--width", f.width, "image width")->capture_default_str();
    app->add_option("--height", f.height, "image height")->capture_default_str();
    app->add_option("--fov", f.fov, "horizontal field of view, degrees")->capture_default_str();
    app->add_option("--encoding", f.encoding, "jpeg, png or raw")->capture_default_str();
    app->add_option("--quality", f.quality, "JPEG quality 1..100")->capture_default_str();
    app->add_option("--cache", f.cache, "server, off or speculative (the inter-frame cache; the server's default is speculative)")
        ->capture_default_str();
    app->add_option("--window", f.window, "adaptive or a fixed W 1..16")->capture_default_str();
    app->add_option("--split", f.split, "server, off, auto or k (the server's default is k = 8192)")->capture_default_str();
    app->add_option("--resort", f.resort,
                    "server, on or off; with the cache: on re-sorts cached frames by the current depth (every frame "
                    "exact); off keeps the key frame's order (the paper's cache and the server's default: faster, "
                    "nearly coplanar layers may swap)")
        ->capture_default_str();
    app->add_option("--reuse-order-max-deg", f.reuse_order_max_deg,
                    "server or degrees 0..180: with --resort off, cached frames keep the key frame's order while "
                    "they have turned at most this much from it (180: always, the paper's cache)")
        ->capture_default_str();
    app->add_option("--max-unacked", f.max_unacked, "frames the server may send ahead of our acknowledgement (1..2)")
        ->capture_default_str();
    app->add_option("--flight-plan", f.flight_plan, "future poses sent with each request (0..16)")->capture_default_str();
    app->add_flag("--no-velocity", f.no_velocity, "do not report the path's velocity");
    app->add_option("--rate", f.rate, "poses per second (0: lock step, next pose when a frame arrives)")
        ->capture_default_str();
    app->add_flag("--lock-step", f.lock_step, "wait for each frame before sending the next pose, at most --rate per second");
}

v1::SessionConfig make_config(const SessionFlags& f) {
    v1::SessionConfig c;
    c.set_scene_id(f.scene);
    if (f.width < 1 || f.height < 1) throw Error("--width/--height must be positive");
    c.set_width(static_cast<std::uint32_t>(f.width));
    c.set_height(static_cast<std::uint32_t>(f.height));
    c.set_horizontal_fov_degrees(f.fov);
    auto* e = c.mutable_encoding();
    if (f.encoding == "jpeg") e->set_encoding(v1::ENCODING_JPEG);
    else if (f.encoding == "png") e->set_encoding(v1::ENCODING_PNG);
    else if (f.encoding == "raw") e->set_encoding(v1::ENCODING_RAW_RGB8);
    else throw Error("--encoding '" + f.encoding + "': expected jpeg, png or raw");
    e->set_jpeg_quality(f.quality);
    auto* p = c.mutable_pipeline();
    if (f.cache == "off") p->set_cache(v1::CACHE_MODE_OFF);
    else if (f.cache == "speculative") p->set_cache(v1::CACHE_MODE_SPECULATIVE);
    else if (f.cache != "server") throw Error("--cache '" + f.cache + "': expected server, speculative or off");
    if (f.window != "adaptive") {
        try {
            p->set_fixed_window(static_cast<std::uint32_t>(std::stoul(f.window)));
        } catch (const std::exception&) {
            throw Error("--window '" + f.window + "': expected adaptive or 1..16");
        }
    }
    if (f.resort == "off") p->set_reuse_depth_order(true);
    else if (f.resort == "on") p->set_reuse_depth_order(false);
    else if (f.resort != "server") throw Error("--resort '" + f.resort + "': expected server, on or off");
    if (f.reuse_order_max_deg != "server") {
        const auto degrees = parse_degrees(f.reuse_order_max_deg);
        if (!degrees)
            throw Error("--reuse-order-max-deg '" + f.reuse_order_max_deg + "': expected server or degrees in 0..180");
        p->set_reuse_order_max_degrees(*degrees);
    }
    if (f.split == "auto") {
        p->set_split(v1::SPLIT_MODE_AUTO);
    } else if (f.split == "off") {
        p->set_split(v1::SPLIT_MODE_OFF);
    } else if (f.split != "server") {
        const auto k = parse_split_k(f.split);
        if (!k) throw Error("--split '" + f.split + "': expected server, off, auto or an integer k in 1..16777216");
        p->set_split(v1::SPLIT_MODE_FIXED);
        p->set_split_k(*k);
    }
    c.set_max_unacked_frames(static_cast<std::uint32_t>(f.max_unacked));
    c.set_client_name("catgs-client");
    if (f.flight_plan < 0 || f.flight_plan > 16) throw Error("--flight-plan: expected 0..16");
    if (!(f.rate >= 0 && f.rate <= 1000)) throw Error("--rate: expected 0..1000 poses per second");
    return c;
}

/// The scene's bounds from GetScene: trajectories are laid over them. Retried on
/// UNAVAILABLE like the streams.
grpc::Status scene_bounds(const Connection& conn, const std::string& scene, Bounds* bounds) {
    auto stub = v1::SceneService::NewStub(conn.channel());
    const std::string auth = conn.authorization();
    v1::GetSceneRequest request;
    request.set_scene_id(scene);
    v1::SceneInfo info;
    grpc::Status s;
    std::mt19937_64 random(conn.retry.seed ? conn.retry.seed : std::random_device{}());
    for (int attempt = 0;; ++attempt) {
        grpc::ClientContext context;
        conn.add_metadata(context, auth);
        context.set_deadline(std::chrono::system_clock::now() + kConnectTimeout);
        s = stub->GetScene(&context, request, &info);
        if (s.error_code() != grpc::StatusCode::UNAVAILABLE || attempt >= conn.retry.retries || g_stop) break;
        const auto delay = client::backoff_delay(conn.retry, attempt + 1, std::uniform_real_distribution<double>(0, 1)(random));
        std::fprintf(stderr, "GetScene: %s (UNAVAILABLE); retrying in %lld ms (%d of %d)\n", s.error_message().c_str(),
                     static_cast<long long>(delay.count()), attempt + 1, conn.retry.retries);
        std::this_thread::sleep_for(delay);
    }
    if (s.ok()) {
        bounds->min = {info.bounds().min().x(), info.bounds().min().y(), info.bounds().min().z()};
        bounds->max = {info.bounds().max().x(), info.bounds().max().y(), info.bounds().max().z()};
    }
    return s;
}

client::StreamPlan make_plan(const Connection& conn, const SessionFlags& f, const Bounds& bounds) {
    client::StreamPlan plan;
    plan.config = make_config(f);
    plan.path = load_trajectory(f.trajectory, bounds, intrinsics_from_fov(f.width, f.height, f.fov));
    if (plan.path.empty()) throw Error("--trajectory '" + f.trajectory + "': no poses");
    plan.poses = plan.path.size();
    plan.rate_hz = f.rate;
    plan.lock_step = f.lock_step;
    plan.flight_plan = f.flight_plan;
    plan.velocity = !f.no_velocity;
    plan.authorization = conn.authorization();
    plan.session_id = conn.session_id;
    return plan;
}

const char* extension(v1::Encoding e) {
    return e == v1::ENCODING_PNG ? "png" : e == v1::ENCODING_RAW_RGB8 ? "rgb" : "jpg";
}

int cmd_stream(const Connection& conn, const SessionFlags& f, const std::string& out, long max_frames) {
    Bounds bounds;
    if (grpc::Status s = scene_bounds(conn, f.scene, &bounds); !s.ok()) {
        std::cerr << "catgs-client: GetScene '" << f.scene << "': " << code_name(s.error_code()) << ": "
                  << s.error_message() << "\n";
        return exit_code(s);
    }
    client::StreamPlan plan = make_plan(conn, f, bounds);
    if (max_frames > 0 && plan.poses > static_cast<std::size_t>(max_frames)) plan.poses = static_cast<std::size_t>(max_frames);
    if (!out.empty()) {
        std::error_code ec;
        std::filesystem::create_directories(out, ec);
        if (ec) throw Error("--out '" + out + "': " + ec.message());
    }
    const std::string pace = f.rate > 0 ? std::to_string(static_cast<int>(std::lround(f.rate))) + " Hz" : "";
    std::printf("streaming %zu poses of %s at %s to %s (%dx%d %s)\n", plan.poses, f.trajectory.c_str(),
                f.rate <= 0 ? "lock step" : f.lock_step ? ("lock step, at most " + pace).c_str() : pace.c_str(),
                conn.server.c_str(), f.width, f.height, f.encoding.c_str());
    std::fflush(stdout);
    // Per-second progress, from the reading thread.
    const Clock::time_point start = Clock::now();
    Clock::time_point window_start = start;
    client::LatencyRecorder window;
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
    client::StreamResult r = client::run_stream_with_retries(
        conn.channel(), plan, on_frame, g_stop, conn.retry, [](const std::string& line) {
            std::fprintf(stderr, "%s\n", line.c_str());
            std::fflush(stderr);
        });
    if (window_frames > 0) report(Clock::now());
    const double secs = std::chrono::duration<double>(Clock::now() - start).count();
    std::printf("summary: %llu poses sent, %llu frames (%.1f fps, %.2f MB), %llu poses coalesced by the server, %llu "
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

int cmd_load(const Connection& conn, const SessionFlags& f, int streams, double duration, const std::string& json_out) {
    if (streams < 1 || streams > 256) throw Error("--streams: expected 1..256");
    if (!(duration > 0 && duration <= 3600)) throw Error("--duration: expected (0, 3600] seconds");
    if (f.rate <= 0) throw Error("--rate: load runs open loop, give a positive pose rate");
    Bounds bounds;
    if (grpc::Status s = scene_bounds(conn, f.scene, &bounds); !s.ok()) {
        std::cerr << "catgs-client: GetScene '" << f.scene << "': " << code_name(s.error_code()) << ": "
                  << s.error_message() << "\n";
        return exit_code(s);
    }
    client::StreamPlan plan = make_plan(conn, f, bounds);
    plan.poses = static_cast<std::size_t>(std::ceil(duration * f.rate));
    plan.max_duration = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(duration));

    std::vector<client::StreamResult> results(static_cast<std::size_t>(streams));
    std::atomic<std::uint64_t> frames_total{0};
    std::vector<std::thread> threads;
    const Clock::time_point start = Clock::now();
    for (int i = 0; i < streams; ++i) {
        threads.emplace_back([&, i] {
            client::StreamPlan mine = plan;
            // Stagger the streams along the path so they do not render identical frames.
            std::rotate(mine.path.begin(), mine.path.begin() + static_cast<long>((i * mine.path.size()) / streams),
                        mine.path.end());
            // One viewer per stream: each keeps its own server behind a proxy.
            mine.session_id = conn.session_id + "-" + std::to_string(i);
            client::RetryPolicy retry = conn.retry;
            if (retry.seed) retry.seed += static_cast<std::uint64_t>(i);
            results[static_cast<std::size_t>(i)] = client::run_stream_with_retries(
                conn.channel(true), mine, [&](const v1::Frame& frame, double) { if (!frame.has_error()) ++frames_total; },
                g_stop, retry, [i](const std::string& line) { std::fprintf(stderr, "[stream %d] %s\n", i, line.c_str()); });
        });
    }
    // Progress once a second while the streams run.
    std::atomic<bool> done{false};
    std::thread progress([&] {
        std::uint64_t last = 0;
        while (!done) {
            std::this_thread::sleep_for(std::chrono::seconds(1));
            if (done) break;
            const std::uint64_t now = frames_total;
            std::fprintf(stderr, "t=%5.1fs  %llu frames/s over %d streams\n",
                         std::chrono::duration<double>(Clock::now() - start).count(),
                         static_cast<unsigned long long>(now - last), streams);
            last = now;
        }
    });
    for (auto& t : threads) t.join();
    done = true;
    progress.join();
    const double elapsed = std::chrono::duration<double>(Clock::now() - start).count();

    client::LatencyRecorder all, ttff;
    std::map<std::string, int> codes;
    std::uint64_t poses = 0, frames = 0, errors = 0, bytes = 0, coalesced = 0, frames_coalesced = 0;
    int reconnects = 0;
    for (const auto& r : results) {
        reconnects += r.reconnects;
        all.merge(r.latency);
        if (r.time_to_first_frame_ms >= 0) ttff.add(r.time_to_first_frame_ms);
        ++codes[code_name(r.status.error_code())];
        poses += r.poses_sent;
        frames += r.frames;
        errors += r.frame_errors;
        bytes += r.bytes;
        coalesced += r.server_poses_coalesced;
        frames_coalesced += r.server_frames_coalesced;
    }
    nlohmann::json report{{"server", conn.server},
                          {"streams", streams},
                          {"duration_s", elapsed},
                          {"rate_hz", f.rate},
                          {"width", f.width},
                          {"height", f.height},
                          {"encoding", f.encoding},
                          {"poses_sent", poses},
                          {"frames", frames},
                          {"frames_per_s", frames / elapsed},
                          {"frames_per_s_per_stream", frames / elapsed / streams},
                          {"megabytes_per_s", bytes / elapsed / 1e6},
                          {"poses_coalesced", coalesced},
                          {"frames_coalesced", frames_coalesced},
                          {"frame_errors", errors},
                          {"reconnects", reconnects},
                          {"latency_ms",
                           {{"p50", all.percentile(0.5)},
                            {"p90", all.percentile(0.9)},
                            {"p95", all.percentile(0.95)},
                            {"p99", all.percentile(0.99)},
                            {"p99.9", all.percentile(0.999)},
                            {"max", all.max()}}},
                          {"time_to_first_frame_ms", {{"p50", ttff.percentile(0.5)}, {"max", ttff.max()}}},
                          {"status_codes", codes}};
    std::printf("load: %d streams x %.1f s at %.0f Hz, %dx%d %s\n", streams, elapsed, f.rate, f.width, f.height,
                f.encoding.c_str());
    std::printf("  %-26s %12llu\n  %-26s %12llu\n  %-26s %12.1f\n  %-26s %12.2f\n  %-26s %12llu\n  %-26s %12llu\n",
                "poses sent", static_cast<unsigned long long>(poses), "frames received",
                static_cast<unsigned long long>(frames), "frames/s (all streams)", frames / elapsed, "MB/s", bytes / elapsed / 1e6,
                "poses coalesced (server)", static_cast<unsigned long long>(coalesced), "frame errors",
                static_cast<unsigned long long>(errors));
    std::printf("  %-26s %12d\n", "reconnects", reconnects);
    std::printf("  latency ms (from intended send time)\n");
    for (const auto& [name, p] : std::vector<std::pair<std::string, double>>{
             {"p50", 0.5}, {"p90", 0.9}, {"p95", 0.95}, {"p99", 0.99}, {"p99.9", 0.999}})
        std::printf("    %-8s %10.1f\n", name.c_str(), all.percentile(p));
    std::printf("    %-8s %10.1f\n", "max", all.max());
    std::printf("  time to first frame ms     p50 %.1f  max %.1f\n", ttff.percentile(0.5), ttff.max());
    std::printf("  status codes:");
    for (const auto& [code, count] : codes) std::printf(" %s=%d", code.c_str(), count);
    std::printf("\n");
    if (!json_out.empty()) {
        std::ofstream file(json_out);
        if (!file) throw Error("--json-out '" + json_out + "': cannot write");
        file << report.dump(2) << "\n";
    }
    for (const auto& r : results)
        if (!r.status.ok()) return exit_code(r.status);
    return kExitOk;
}

nlohmann::json scene_json(const v1::SceneInfo& s) {
    return {{"scene_id", s.scene_id()},
            {"source", s.source()},
            {"gaussians", s.gaussian_count()},
            {"sh_degree", s.sh_degree()},
            {"bounds_min", {s.bounds().min().x(), s.bounds().min().y(), s.bounds().min().z()}},
            {"bounds_max", {s.bounds().max().x(), s.bounds().max().y(), s.bounds().max().z()}},
            {"host_bytes", s.host_bytes()},
            {"device_bytes", s.device_bytes()},
            {"sessions", s.sessions()},
            {"state", s.state() == v1::SCENE_STATE_UNLOADING ? "unloading" : "ready"}};
}

void print_scene(const v1::SceneInfo& s) {
    std::printf("%-16s %10llu Gaussians  SH %d  %8.1f MB  %u sessions  %-9s  %s\n", s.scene_id().c_str(),
                static_cast<unsigned long long>(s.gaussian_count()), s.sh_degree(), s.host_bytes() / 1e6, s.sessions(),
                s.state() == v1::SCENE_STATE_UNLOADING ? "unloading" : "ready", s.source().c_str());
}

int cmd_scenes(const Connection& conn, const std::string& action, const std::string& arg, const std::string& id,
               bool drop_invalid, bool json) {
    auto stub = v1::SceneService::NewStub(conn.channel());
    grpc::ClientContext context;
    conn.add_metadata(context, conn.authorization());
    context.set_wait_for_ready(true);
    // Loading a large scene takes a while; the rest is immediate.
    context.set_deadline(std::chrono::system_clock::now() + (action == "load" ? std::chrono::seconds(600) : kConnectTimeout));
    grpc::Status status;
    nlohmann::json out;
    if (action == "list") {
        v1::ListScenesResponse response;
        status = stub->ListScenes(&context, {}, &response);
        out = nlohmann::json::array();
        for (const auto& s : response.scenes()) {
            if (json) out.push_back(scene_json(s));
            else print_scene(s);
        }
    } else if (action == "get" || action == "load" || action == "unload") {
        if (arg.empty()) throw Error("scenes " + action + ": missing " + (action == "load" ? "SOURCE" : "ID"));
        if (action == "get") {
            v1::GetSceneRequest request;
            request.set_scene_id(arg);
            v1::SceneInfo info;
            status = stub->GetScene(&context, request, &info);
            if (status.ok()) json ? void(out = scene_json(info)) : print_scene(info);
        } else if (action == "load") {
            v1::LoadSceneRequest request;
            request.set_source(arg);
            request.set_scene_id(id);
            request.set_drop_invalid(drop_invalid);
            v1::SceneInfo info;
            if (!json) std::fprintf(stderr, "loading %s ...\n", arg.c_str());
            status = stub->LoadScene(&context, request, &info);
            if (status.ok()) json ? void(out = scene_json(info)) : print_scene(info);
        } else {
            v1::UnloadSceneRequest request;
            request.set_scene_id(arg);
            v1::UnloadSceneResponse response;
            status = stub->UnloadScene(&context, request, &response);
            if (status.ok()) {
                if (json) out = {{"scene", scene_json(response.scene())}, {"freed", response.freed()}};
                else std::printf("%s: %s\n", arg.c_str(), response.freed() ? "freed" : "unloading (freed when its sessions close)");
            }
        }
    } else {
        throw Error("scenes: unknown action '" + action + "' (expected list, get, load or unload)");
    }
    if (!status.ok()) {
        std::cerr << "catgs-client: scenes " << action << ": " << code_name(status.error_code()) << ": "
                  << status.error_message() << "\n";
        return exit_code(status);
    }
    if (json) std::cout << out.dump(2) << "\n";
    return kExitOk;
}

}  // namespace

int main(int argc, char** argv) {
    Connection conn;
    SessionFlags session;
    std::string out, json_out, scene_action, scene_arg, scene_id;
    long max_frames = -1;
    int streams = 4;
    double duration = 10;
    bool drop_invalid = false, json = false;

    CLI::App app{"catgs-client: stream frames from catgs-server, load-test it, manage its scenes"};
    app.require_subcommand(1);
    app.add_option("--server", conn.server, "server address host:port")->capture_default_str();
    app.add_option("--token-file", conn.token_file, "send 'authorization: Bearer <first line of the file>'");
    app.add_option("--session-id", conn.session_id,
                   "sent as metadata 'x-catgs-session' on every call, so that a front proxy sends a reconnecting "
                   "client back to the server that holds its scene warm (load: ID-N for stream N; default: random "
                   "per run)");
    app.add_flag("--tls", conn.tls, "connect with TLS (system roots unless --tls-ca)");
    app.add_option("--tls-ca", conn.tls_ca, "PEM CA bundle to verify the server (implies --tls)");
    app.add_option("--tls-cert", conn.tls_cert, "PEM client certificate chain for mutual TLS (with --tls-key; implies --tls)");
    app.add_option("--tls-key", conn.tls_key, "PEM private key of --tls-cert");
    int retries = conn.retry.retries;
    long backoff_ms = conn.retry.backoff.count(), max_backoff_ms = conn.retry.max_backoff.count();
    app.add_option("--retries", retries,
                   "stream and load: on UNAVAILABLE (server down, restarting or draining) reconnect up to this many "
                   "times in a row, resuming the trajectory in a new session (0: fail at once)")
        ->capture_default_str();
    app.add_option("--backoff-ms", backoff_ms,
                   "first reconnection delay; the n-th retry in a row waits a random time between half and all of "
                   "min(--max-backoff-ms, backoff * 2^(n-1))")
        ->capture_default_str();
    app.add_option("--max-backoff-ms", max_backoff_ms, "longest reconnection delay")->capture_default_str();
    app.add_option("--retry-seed", conn.retry.seed, "seed of the backoff jitter (0: from the clock)");

    CLI::App* stream = app.add_subcommand("stream", "stream one trajectory, print latency and fps each second");
    add_session_flags(stream, session);
    stream->add_option("--out", out, "directory for the received frames (encoded bytes: .jpg, .png or .rgb)");
    stream->add_option("--max-frames", max_frames, "send at most this many poses");

    CLI::App* load = app.add_subcommand("load", "N concurrent open-loop streams; latency percentiles and a JSON report");
    add_session_flags(load, session);
    load->add_option("--streams", streams, "concurrent streams")->capture_default_str();
    load->add_option("--duration", duration, "seconds")->capture_default_str();
    load->add_option("--json-out", json_out, "write the report as JSON to this file");

    CLI::App* scenes = app.add_subcommand("scenes", "list | get ID | load SOURCE [--id ID] | unload ID");
    scenes->add_option("action", scene_action, "list, get, load or unload")->required();
    scenes->add_option("argument", scene_arg, "scene id, or the source to load");
    scenes->add_option("--id", scene_id, "id for a loaded scene (default: derived from the source)");
    scenes->add_flag("--drop-invalid", drop_invalid, "drop invalid records when loading");
    scenes->add_flag("--json", json, "machine-readable output");

    try {
        app.parse(argc, argv);
    } catch (const CLI::CallForHelp& e) {
        return app.exit(e);
    } catch (const CLI::CallForAllHelp& e) {
        return app.exit(e);
    } catch (const CLI::ParseError& e) {
        std::cerr << "catgs-client: " << e.what() << "\n";
        return kExitBadInput;
    }
    if (retries < 0 || retries > 1000) {
        std::cerr << "catgs-client: --retries: expected 0..1000\n";
        return kExitBadInput;
    }
    if (backoff_ms < 1 || max_backoff_ms < backoff_ms || max_backoff_ms > 600'000) {
        std::cerr << "catgs-client: --backoff-ms/--max-backoff-ms: expected 1 <= backoff <= max backoff <= 600000\n";
        return kExitBadInput;
    }
    if (conn.session_id.empty()) {
        char id[17];
        std::snprintf(id, sizeof id, "%016llx", static_cast<unsigned long long>(std::random_device{}()) << 32 ^
                                                    static_cast<unsigned long long>(std::random_device{}()));
        conn.session_id = id;
    } else if (!client::valid_session_id(conn.session_id)) {
        std::cerr << "catgs-client: --session-id: expected 1.." << client::kMaxSessionIdLength
                  << " printable ASCII characters (an HTTP/2 header value)\n";
        return kExitBadInput;
    }
    conn.retry.retries = retries;
    conn.retry.backoff = std::chrono::milliseconds(backoff_ms);
    conn.retry.max_backoff = std::chrono::milliseconds(max_backoff_ms);
    std::signal(SIGINT, on_signal);
    std::signal(SIGTERM, on_signal);
    try {
        if (stream->parsed()) return cmd_stream(conn, session, out, max_frames);
        if (load->parsed()) return cmd_load(conn, session, streams, duration, json_out);
        return cmd_scenes(conn, scene_action, scene_arg, scene_id, drop_invalid, json);
    } catch (const Error& e) {
        std::cerr << "catgs-client: " << e.what() << "\n";
        return kExitBadInput;
    } catch (const std::exception& e) {
        std::cerr << "catgs-client: failed: " << e.what() << "\n";
        return kExitFailure;
    }
}
