#include "session_flags.hpp"

#include <chrono>
#include <cstdio>
#include <random>
#include <thread>

#include "catgs/common/command_line.hpp"
#include "catgs/error.hpp"
#include "catgs/render_options.hpp"
#include "catgs/trajectory.hpp"
#include "stop.hpp"

namespace catgs::client {

void add_session_flags(CLI::App* app, SessionFlags& f) {
    app->add_option("--scene", f.scene, "scene id on the server")->capture_default_str();
    app->add_option("--trajectory", f.trajectory,
                    "trajectory file or builtin:survey|orbit|flythrough|hover?... laid over the scene's bounds")
        ->capture_default_str();
    app->add_option("--width", f.width, "image width")->check(image_side())->capture_default_str();
    app->add_option("--height", f.height, "image height")->check(image_side())->capture_default_str();
    app->add_option("--fov", f.fov, "horizontal field of view, degrees")
        ->check(horizontal_fov())
        ->capture_default_str();
    app->add_option("--encoding", f.encoding, "jpeg, png or raw")->capture_default_str();
    app->add_option("--quality", f.quality, "JPEG quality 1..100")->check(jpeg_quality())->capture_default_str();
    app->add_option("--cache", f.cache,
                    "server, off or speculative (the inter-frame cache; the server's default is speculative)")
        ->capture_default_str();
    app->add_option("--window", f.window, "adaptive or a fixed W 1..16")->capture_default_str();
    app->add_option("--split", f.split, "server, off, auto or k (the server's default is k = 8192)")
        ->capture_default_str();
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
        ->check(CLI::Range(1, 2))
        ->capture_default_str();
    app->add_option("--flight-plan", f.flight_plan, "future poses sent with each request (0..16)")
        ->check(CLI::Range(0, 16))
        ->capture_default_str();
    app->add_flag("--no-velocity", f.no_velocity, "do not report the path's velocity");
    app->add_option("--rate", f.rate, "poses per second (0: lock step, next pose when a frame arrives)")
        ->check(bounded_number(0, 1000, "poses per second"))
        ->capture_default_str();
    app->add_flag("--lock-step", f.lock_step,
                  "wait for each frame before sending the next pose, at most --rate per second");
}

v1::SessionConfig make_config(const SessionFlags& f) {
    v1::SessionConfig c;
    c.set_scene_id(f.scene);
    if (f.width < 1 || f.height < 1) throw Error("--width/--height must be positive");
    c.set_width(static_cast<std::uint32_t>(f.width));
    c.set_height(static_cast<std::uint32_t>(f.height));
    c.set_horizontal_fov_degrees(f.fov);
    auto* e = c.mutable_encoding();
    if (f.encoding == "jpeg")
        e->set_encoding(v1::ENCODING_JPEG);
    else if (f.encoding == "png")
        e->set_encoding(v1::ENCODING_PNG);
    else if (f.encoding == "raw")
        e->set_encoding(v1::ENCODING_RAW_RGB8);
    else
        throw Error("--encoding '" + f.encoding + "': expected jpeg, png or raw");
    e->set_jpeg_quality(f.quality);
    auto* p = c.mutable_pipeline();
    if (f.cache == "off")
        p->set_cache(v1::CACHE_MODE_OFF);
    else if (f.cache == "speculative")
        p->set_cache(v1::CACHE_MODE_SPECULATIVE);
    else if (f.cache != "server")
        throw Error("--cache '" + f.cache + "': expected server, speculative or off");
    if (f.window != "adaptive") {
        try {
            p->set_fixed_window(static_cast<std::uint32_t>(std::stoul(f.window)));
        } catch (const std::exception&) {
            throw Error("--window '" + f.window + "': expected adaptive or 1..16");
        }
    }
    if (f.resort == "off")
        p->set_reuse_depth_order(true);
    else if (f.resort == "on")
        p->set_reuse_depth_order(false);
    else if (f.resort != "server")
        throw Error("--resort '" + f.resort + "': expected server, on or off");
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
        if (s.error_code() != grpc::StatusCode::UNAVAILABLE || attempt >= conn.retry.retries || stop_requested()) break;
        const auto delay = backoff_delay(conn.retry, attempt + 1, std::uniform_real_distribution<double>(0, 1)(random));
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

StreamPlan make_plan(const Connection& conn, const SessionFlags& f, const Bounds& bounds) {
    StreamPlan plan;
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

}  // namespace catgs::client
