// catgs-client: talks to catgs-server.
//   stream  one session along a trajectory; saves frames, prints latency and fps per second
//   load    N concurrent open-loop sessions for a duration; latency percentiles, JSON report
//   scenes  list | get ID | load SOURCE | unload ID
// Exit status: 0 success; 1 the RPC failed otherwise; 2 bad input (one line on stderr);
// 3 server unreachable or shutting down (UNAVAILABLE after --retries reconnections,
// DEADLINE_EXCEEDED); 4 refused by a server limit (RESOURCE_EXHAUSTED); 5 not authenticated
// (UNAUTHENTICATED, PERMISSION_DENIED);
// 6 the server rejected the request (INVALID_ARGUMENT, NOT_FOUND, FAILED_PRECONDITION,
// ALREADY_EXISTS). The numbers are catgs/common/exit_codes.hpp.
#include <CLI/CLI.hpp>

#include "catgs/common/command_line.hpp"
#include "commands.hpp"
#include "connection.hpp"
#include "stop.hpp"

int main(int argc, char** argv) {
    using namespace catgs;
    using namespace catgs::client;
    ConnectionFlags connection;
    StreamArgs stream_args;
    LoadArgs load_args;
    ScenesArgs scenes_args;

    CLI::App app{"catgs-client: stream frames from catgs-server, load-test it, manage its scenes"};
    app.require_subcommand(1);
    add_connection_flags(app, connection);
    CLI::App* stream = add_stream_command(app, stream_args);
    CLI::App* load = add_load_command(app, load_args);
    add_scenes_command(app, scenes_args);

    return catgs::run_command_line(app, argc, argv, "catgs-client", [&] {
        const Connection conn = make_connection(connection);
        stop_on_signals();
        if (stream->parsed()) return run_stream_command(conn, stream_args);
        if (load->parsed()) return run_load_command(conn, load_args);
        return run_scenes_command(conn, scenes_args);
    });
}
