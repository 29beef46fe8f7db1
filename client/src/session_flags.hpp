// The flags of one render session, shared by `stream` and `load`, and what they become: the
// SessionConfig the server gets and the StreamPlan the runner follows.
#pragma once

#include <CLI/CLI.hpp>
#include <grpcpp/grpcpp.h>

#include <string>

#include "catgs/scene.hpp"
#include "connection.hpp"
#include "stream_runner.hpp"

namespace catgs::client {

struct SessionFlags {
    std::string scene = "city";
    std::string trajectory = "builtin:survey";
    int width = 960, height = 540;
    double fov = 70;
    std::string encoding = "jpeg";
    int quality = 85;
    // "server": leave the field unset, so the server's default applies (docs/pipeline.md, "Defaults, and why").
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

void add_session_flags(CLI::App* app, SessionFlags& f);

/// Throws catgs::Error naming the flag.
v1::SessionConfig make_config(const SessionFlags& f);

/// The scene's bounds from GetScene: trajectories are laid over them. Retried on
/// UNAVAILABLE like the streams.
grpc::Status scene_bounds(const Connection& conn, const std::string& scene, Bounds* bounds);

/// The session's config and its path laid over `bounds`; throws catgs::Error naming the flag.
StreamPlan make_plan(const Connection& conn, const SessionFlags& f, const Bounds& bounds);

}  // namespace catgs::client
