// catgs-server: the streaming render server. Exit status: 0 after a clean shutdown, 2 on bad
// flags or configuration (one line on stderr naming the problem), 1 on other failures.
#include <CLI/CLI.hpp>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <csignal>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <thread>

#include "catgs/common/command_line.hpp"
#include "catgs/common/exit_codes.hpp"
#include "catgs/common/files.hpp"
#include "catgs/error.hpp"
#include "catgs/gpu_queues.hpp"
#include "catgs/renderer.hpp"
#include "catgs/server/device_placement.hpp"
#include "catgs/server/encoder.hpp"
#include "catgs/server/server.hpp"

namespace {

constexpr std::uint64_t kMiB = 1024 * 1024;

std::string default_backend() {
    try {
        catgs::make_renderer("cuda", catgs::Precision::single, 1);
        return "cuda";
    } catch (const std::exception&) {
        return "cpu";
    }
}

/// The command line: ServerOptions and what main turns into them.
struct CommandLine {
    catgs::server::ServerOptions o;
    std::vector<std::string> scenes;
    std::string gpus;
    CLI::Option* gpus_option = nullptr;
    std::uint64_t max_scene_mb = 0, max_session_mb = 0;
    std::string token_file, log_level = "info";
    bool no_reflection = false;
    bool no_prewarm = false;
    std::string jpeg_encoder = "auto";
    catgs::server::EncoderOptions encoder_options;
};

/// Where the server listens, what it serves and on which devices.
void add_serving_options(CLI::App& app, CommandLine& c) {
    catgs::server::ServerOptions& o = c.o;
    app.add_option("--address", o.address, "listen address host:port (port 0 picks a free one; it is printed)")
        ->capture_default_str();
    app.add_option("--health-address", o.health_address,
                   "extra plaintext listener serving only grpc.health.v1 (for Kubernetes probes)");
    o.web_root = CATGS_DEFAULT_WEB_ROOT;
    app.add_option("--web-address", o.web_address,
                   "serve the browser viewer, /api/ unary calls and the /ws/stream WebSocket on this host:port "
                   "(HTTPS/WSS with --tls-cert, the same --token-file; port 0 picks a free one; off by default; "
                   "docs/web.md)");
    app.add_option("--web-root", o.web_root, "the viewer's static files, served by --web-address")
        ->capture_default_str();
    app.add_option("--scene-root", o.scene_root, "directory that SceneService.LoadScene paths are resolved in");
    app.add_option(
        "--scene", c.scenes,
        "scene to load at start-up, [ID=]PATH|builtin:...; repeatable (default city=" + o.preload[0].substr(5) + ")");
    app.add_flag("--no-prewarm", c.no_prewarm,
                 "CUDA: do not upload the start-up scenes to the GPUs before their first session (by default an idle "
                 "renderer on each GPU holds them there, so the first viewer does not wait for the upload)");
    app.add_option(
        "--backend", o.backend,
        "cpu or cuda (default: cuda when a device is usable, else cpu; built in: " + catgs::available_backends() + ")");
    c.gpus_option = app.add_option(
        "--gpus", c.gpus,
        "devices to place sessions on: all, N (devices 0..N-1) or a list of indices such as 0,2; each new session "
        "goes to the device with the least measured render time per second, and --max-sessions counts per device. "
        "CPU backend: N simulated devices (own renderers, scene residency and load, sharing the host's cores; all: "
        "1). Default: device 0 alone (docs/multi-gpu.md)");
    app.add_option("--precision", o.precision, "float or double")->capture_default_str();
}

/// How renders and encodes are spread over threads.
void add_worker_options(CLI::App& app, CommandLine& c) {
    catgs::server::ServerOptions& o = c.o;
    app.add_option("--render-threads", o.render_threads, "CPU backend: threads per render (0: all cores)")
        ->check(catgs::thread_count())
        ->capture_default_str();
    app.add_option("--render-workers", o.render_workers,
                   "sessions rendering at the same time (" + catgs::server::auto_worker_counts_help() + ")")
        ->check(catgs::thread_count())
        ->capture_default_str();
    app.add_option("--encode-workers", o.encode_workers, "JPEG/PNG encoder threads (0: auto, see --render-workers)")
        ->check(catgs::thread_count())
        ->capture_default_str();
    app.add_option("--jpeg-encoder", c.jpeg_encoder,
                   "auto (nvJPEG when built in and a GPU is usable, else TurboJPEG), turbo or nvjpeg")
        ->capture_default_str();
    app.add_option("--encode-threads", c.encoder_options.threads,
                   "threads one frame's JPEG strips or PNG chunks are spread over (0: all cores)")
        ->check(catgs::thread_count())
        ->capture_default_str();
}

/// What one client, or all of them together, may ask of the server.
void add_limit_options(CLI::App& app, CommandLine& c) {
    catgs::server::Limits& l = c.o.limits;
    app.add_option("--max-sessions", l.max_sessions, "concurrent sessions (per GPU)")->capture_default_str();
    app.add_option("--max-width", l.max_width, "largest image width a session may request")->capture_default_str();
    app.add_option("--max-height", l.max_height, "largest image height a session may request")->capture_default_str();
    app.add_option("--max-scene-mb", c.max_scene_mb,
                   "memory of all loaded scenes together, MiB; LoadScene beyond it is RESOURCE_EXHAUSTED (0: no limit)")
        ->capture_default_str();
    app.add_option("--max-session-mb", c.max_session_mb,
                   "renderer memory one session may hold (GPU arenas), MiB; a session above it ends with "
                   "RESOURCE_EXHAUSTED (0: no limit)")
        ->capture_default_str();
    app.add_option("--max-pose-rate", l.max_pose_rate,
                   "frame requests per second per stream, burst of one second; faster clients are read more slowly "
                   "(0: no limit)")
        ->capture_default_str();
    app.add_option("--stall-timeout-ms", l.stall_timeout_ms,
                   "cancel a stream whose client has not read a frame for this long, DEADLINE_EXCEEDED (0: never)")
        ->capture_default_str();
    app.add_option("--open-timeout-ms", l.open_timeout_ms,
                   "finish a stream that has not sent its opening message this long after it started, "
                   "DEADLINE_EXCEEDED (0: never)")
        ->capture_default_str();
}

/// Security, shutdown and logging.
void add_operation_options(CLI::App& app, CommandLine& c) {
    catgs::server::ServerOptions& o = c.o;
    app.add_option("--tls-cert", o.tls_cert_file, "PEM certificate chain (with --tls-key: serve TLS)");
    app.add_option("--tls-key", o.tls_key_file, "PEM private key");
    app.add_option("--tls-client-ca", o.tls_client_ca_file, "PEM CA bundle: require client certificates (mTLS)");
    app.add_option("--token-file", c.token_file,
                   "require 'authorization: Bearer <token>' metadata; the token is the file's first line "
                   "(health checks stay open)");
    app.add_flag("--no-reflection", c.no_reflection,
                 "do not serve gRPC server reflection (it is always off with --token-file)");
    app.add_option("--drain-ms", o.drain_ms,
                   "on SIGTERM/SIGINT: health turns NOT_SERVING and open streams are told to reconnect at once; the "
                   "listeners stay open this long, refusing new sessions with UNAVAILABLE, before the server stops")
        ->capture_default_str();
    app.add_option("--shutdown-grace-ms", o.shutdown_grace_ms,
                   "after the drain, time given to unary calls still running before they are cancelled")
        ->capture_default_str();
    app.add_option("--log-level", c.log_level, "trace, debug, info, warn, error")->capture_default_str();
}

/// Checks the parsed values and completes the ServerOptions from them; throws catgs::Error
/// naming the flag.
void finish_options(CommandLine& c) {
    catgs::server::ServerOptions& o = c.o;
    if (!c.scenes.empty()) o.preload = c.scenes;
    if (o.backend.empty()) o.backend = default_backend();
    if (c.gpus_option->count() > 0)
        o.devices = catgs::server::parse_gpus(
            c.gpus, o.backend == "cuda" ? std::optional<int>(catgs::device_count("cuda")) : std::nullopt);
    o.limits.max_scene_bytes = c.max_scene_mb * kMiB;
    o.limits.max_session_bytes = c.max_session_mb * kMiB;
    if (!(o.limits.max_pose_rate >= 0)) throw catgs::Error("--max-pose-rate must be >= 0");
    if (o.limits.stall_timeout_ms < 0) throw catgs::Error("--stall-timeout-ms must be >= 0");
    if (o.limits.open_timeout_ms < 0) throw catgs::Error("--open-timeout-ms must be >= 0");
    if (o.drain_ms < 0 || o.shutdown_grace_ms < 0) throw catgs::Error("--drain-ms/--shutdown-grace-ms must be >= 0");
    if (!c.token_file.empty()) o.bearer_token = catgs::read_token(c.token_file);
    o.reflection = !c.no_reflection;
    o.prewarm = !c.no_prewarm;
    if (o.limits.max_sessions < 1) throw catgs::Error("--max-sessions must be >= 1");
    if (o.limits.max_width < 1 || o.limits.max_height < 1) throw catgs::Error("--max-width/--max-height must be >= 1");
    if (!o.bearer_token.empty() && o.tls_cert_file.empty())
        spdlog::warn("bearer token over plaintext: anyone on the path can read it; use --tls-cert/--tls-key");
    c.encoder_options.jpeg = catgs::server::parse_jpeg_encoder(c.jpeg_encoder);
}

}  // namespace

int main(int argc, char** argv) {
    catgs::request_gpu_hardware_queues();
    catgs::request_eager_kernel_loading();
    CommandLine c;
    c.o.backend = "";
    CLI::App app{"catgs-server: streams rendered 3D Gaussian Splatting frames over gRPC (catgs.v1)"};
    add_serving_options(app, c);
    add_worker_options(app, c);
    add_limit_options(app, c);
    add_operation_options(app, c);
    if (const std::optional<int> status = catgs::parse_command_line(app, argc, argv, "catgs-server")) return *status;

    // SIGINT/SIGTERM are handled by one thread with sigwait; blocking them here, before any
    // thread starts, makes every other thread inherit the mask.
    sigset_t signals;
    sigemptyset(&signals);
    sigaddset(&signals, SIGINT);
    sigaddset(&signals, SIGTERM);
    pthread_sigmask(SIG_BLOCK, &signals, nullptr);

    std::unique_ptr<catgs::server::Server> server;
    const int started = catgs::run_reporting_errors("catgs-server", [&] {
        // Logs go to stderr: stdout carries only the "listening on port" line for scripts.
        spdlog::set_default_logger(spdlog::stderr_color_mt("catgs-server"));
        spdlog::set_level(spdlog::level::from_str(c.log_level));
        finish_options(c);
        catgs::server::configure_encoder(c.encoder_options);
        spdlog::info("jpeg encoder: {}", catgs::server::jpeg_encoder_name(catgs::server::configured_jpeg_encoder()));
        server = std::make_unique<catgs::server::Server>(c.o);
        server->start();
        return catgs::kExitOk;
    });
    if (started != catgs::kExitOk) return started;
    // For scripts and tests that start the server on port 0.
    std::printf("catgs-server: listening on port %d\n", server->port());
    if (!server->web_url().empty()) std::printf("catgs-server: web viewer on %s\n", server->web_url().c_str());
    std::fflush(stdout);

    std::thread waiter([&] {
        int signal = 0;
        sigwait(&signals, &signal);
        spdlog::info("received {}", signal == SIGTERM ? "SIGTERM" : "SIGINT");
        server->drain_and_shutdown();
    });
    server->wait();
    waiter.join();
    server.reset();
    return 0;
}
