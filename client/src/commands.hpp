// The subcommands of catgs-client, one file each: their flags and what they run. Each run_*
// returns the process's exit status (catgs/common/exit_codes.hpp) and throws catgs::Error
// for bad input.
#pragma once

#include <CLI/CLI.hpp>

#include <string>

#include "connection.hpp"
#include "session_flags.hpp"

namespace catgs::client {

/// stream: one session along a trajectory; saves frames, prints latency and fps per second.
struct StreamArgs {
    SessionFlags session;
    std::string out;
    long max_frames = -1;
};
CLI::App* add_stream_command(CLI::App& app, StreamArgs& args);
int run_stream_command(const Connection& conn, const StreamArgs& args);

/// load: N concurrent open-loop sessions for a duration; latency percentiles, JSON report.
struct LoadArgs {
    SessionFlags session;
    int streams = 4;
    double duration = 10;
    std::string json_out;
};
CLI::App* add_load_command(CLI::App& app, LoadArgs& args);
int run_load_command(const Connection& conn, const LoadArgs& args);

/// scenes: list | get ID | load SOURCE | unload ID.
struct ScenesArgs {
    std::string action, argument, id;
    bool drop_invalid = false, json = false;
};
CLI::App* add_scenes_command(CLI::App& app, ScenesArgs& args);
int run_scenes_command(const Connection& conn, const ScenesArgs& args);

}  // namespace catgs::client
