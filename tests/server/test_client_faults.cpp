// The client's side of faults: the server killed and restarted under a streaming client,
// which reconnects and completes its path; a server gone for good, after which the client
// gives up; and the load client's report, whose counts a user reads against the schedule.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <regex>

#include "process_util.hpp"
#include "server_test_util.hpp"

namespace catgs::test {
namespace {

namespace fs = std::filesystem;

// ---------------------------------------------------------------------------------------
// The server restarted on the same port while a client streams: the client reconnects with
// backoff, resumes in a new session and completes its trajectory.
// ---------------------------------------------------------------------------------------

TEST(ClientFaults, ServerRestartedWhileTheClientReconnects) {
    const std::uint64_t seed = test_seed("ServerRestartedWhileTheClientReconnects");
    const std::vector<std::string> server_flags = {
        "--backend", "cpu", "--scene", "city=builtin:city?gaussians=10000&seed=1", "--render-threads", "1"};
    auto start = [&](const std::string& address) {
        std::vector<std::string> argv = {CATGS_SERVER_BINARY, "--address", address};
        argv.insert(argv.end(), server_flags.begin(), server_flags.end());
        return std::make_unique<Child>(argv);
    };
    auto server = start("127.0.0.1:0");
    const int port = wait_for_port(*server);
    ASSERT_GT(port, 0) << server->output();
    constexpr int kPoses = 60;
    Child client({CATGS_CLIENT_BINARY,
                  "--server",
                  "127.0.0.1:" + std::to_string(port),
                  "--retries",
                  "20",
                  "--backoff-ms",
                  "100",
                  "--max-backoff-ms",
                  "800",
                  "--retry-seed",
                  std::to_string(seed),
                  "stream",
                  "--scene",
                  "city",
                  "--trajectory",
                  "builtin:hover?frames=" + std::to_string(kPoses),
                  "--width",
                  "160",
                  "--height",
                  "90",
                  "--rate",
                  "20",
                  "--lock-step"});
    // Frames flow for a second (the client prints its first progress line)...
    ASSERT_TRUE(client.wait_for_output(" fps  latency p50", std::chrono::milliseconds(20000))) << client.output();
    ASSERT_TRUE(client.running()) << client.output();
    // ...then the server dies without a word, and comes back on the same port a little later.
    server->kill(SIGKILL);
    ASSERT_EQ(server->wait(std::chrono::seconds(10)).value_or(-1), 128 + SIGKILL);
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
    server = start("127.0.0.1:" + std::to_string(port));
    ASSERT_EQ(wait_for_port(*server), port) << server->output();

    const auto code = client.wait(std::chrono::seconds(60));
    const std::string out = client.output();
    ASSERT_TRUE(code.has_value()) << "the client did not finish\n" << out;
    EXPECT_EQ(*code, 0) << out;
    EXPECT_NE(out.find("(UNAVAILABLE); reconnecting in "), std::string::npos) << out;
    // Lock step: every pose got exactly one frame, across both sessions; none coalesced.
    EXPECT_NE(out.find(" " + std::to_string(kPoses) + " frames ("), std::string::npos) << out;
    EXPECT_NE(out.find(" 0 poses coalesced by the server, 0 frame errors"), std::string::npos) << out;
    EXPECT_NE(out.find("status OK"), std::string::npos) << out;
    EXPECT_EQ(out.find(" 0 reconnects"), std::string::npos) << out;
    server->kill(SIGTERM);
    EXPECT_EQ(server->wait(std::chrono::seconds(10)).value_or(-1), 0) << server->output();
}

/// With the server gone for good, the client gives up after --retries and exits 3.
TEST(ClientFaults, ClientGivesUpAfterItsRetries) {
    // A port nobody listens on: bind one, note it, close it.
    int fd = socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    ASSERT_EQ(bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr), 0);
    socklen_t len = sizeof addr;
    getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len);
    close(fd);
    const int port = ntohs(addr.sin_port);
    const auto begin = std::chrono::steady_clock::now();
    Child client({CATGS_CLIENT_BINARY, "--server", "127.0.0.1:" + std::to_string(port), "--retries", "3",
                  "--backoff-ms", "50", "--max-backoff-ms", "200", "stream", "--scene", "city"});
    const auto code = client.wait(std::chrono::seconds(30));
    ASSERT_TRUE(code.has_value()) << client.output();
    EXPECT_EQ(*code, 3) << client.output();
    EXPECT_NE(client.output().find("GetScene: "), std::string::npos) << client.output();
    EXPECT_NE(client.output().find("retrying in"), std::string::npos) << client.output();
    EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - begin).count(), 25.0);
}

/// A load run's JSON report and console output, `flags` after `load --scene city`.
struct LoadRun {
    std::string report, output;
};
LoadRun run_load(const server::Server& server, const std::string& tag, const std::vector<std::string>& flags) {
    const fs::path json = fs::path(CATGS_TEST_TMP) / (tag + "-" + std::to_string(getpid()) + ".json");
    fs::create_directories(json.parent_path());
    std::vector<std::string> argv = {
        CATGS_CLIENT_BINARY, "--server", "127.0.0.1:" + std::to_string(server.port()), "load", "--scene", "city"};
    argv.insert(argv.end(), flags.begin(), flags.end());
    argv.insert(argv.end(), {"--json-out", json.string()});
    Child client(argv);
    const auto code = client.wait(std::chrono::seconds(60));
    EXPECT_TRUE(code.has_value()) << client.output();
    EXPECT_EQ(code.value_or(-1), 0) << client.output();
    std::ifstream file(json);
    LoadRun run{std::string((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>()), client.output()};
    fs::remove(json);
    return run;
}

/// A number of the report, or -1 (and a failure) where it is missing.
double report_field(const LoadRun& run, const std::string& name) {
    std::smatch m;
    const std::regex pattern("\"" + name + "\": ([-+0-9.eE]+)");
    EXPECT_TRUE(std::regex_search(run.report, m, pattern)) << name << " missing in\n" << run.report << run.output;
    return m.empty() ? -1.0 : std::stod(m[1].str());
}

/// The load client's report counts against the poses' schedule as well as the wall time: the
/// wall time includes each stream's setup and its last frame, so a server answering every pose
/// shows streams x rate frames/s only over the schedule. Both must follow from the counts.
TEST(ClientFaults, LoadReportCountsFramesAgainstThePosesSchedule) {
    auto server = start_server();
    const LoadRun run =
        run_load(*server, "load-report",
                 {"--streams", "2", "--duration", "2", "--rate", "15", "--width", "160", "--height", "90"});
    const auto field = [&](const std::string& name) { return report_field(run, name); };
    const double poses = field("poses_sent"), frames = field("frames"), schedule = field("schedule_s");
    // 2 streams x 2 s x 15 Hz planned; a stream whose opening took long ends a pose or two early.
    EXPECT_GT(poses, 0);
    EXPECT_LE(poses, 2 * 30);
    EXPECT_DOUBLE_EQ(schedule, 2.0);
    EXPECT_GT(frames, 0);
    EXPECT_LE(frames, poses);
    EXPECT_NEAR(field("frames_per_s_of_schedule"), frames / schedule, 1e-9);
    EXPECT_NEAR(field("poses_served"), frames / poses, 1e-9);
    // The last pose leaves one period (1/15 s) before the schedule's end; the wall time holds
    // its frame and the setup.
    EXPECT_GT(field("duration_s"), schedule - 1.0 / 15) << "the wall time includes the last pose's frame";
    EXPECT_NE(run.output.find("poses served"), std::string::npos) << run.output;
}

/// The wall time ends with the last stream. The once-a-second progress line used to sleep past
/// it, adding up to a second to a 12-second run and taking 8% off its frames/s.
TEST(ClientFaults, LoadWallTimeEndsWithTheLastStream) {
    auto server = start_server();
    // Two poses a stream, at 0 and 0.25 s: the streams end long before the first progress line.
    const LoadRun run =
        run_load(*server, "load-wall",
                 {"--streams", "2", "--duration", "0.5", "--rate", "4", "--width", "64", "--height", "48"});
    const double wall = report_field(run, "duration_s");
    EXPECT_GT(wall, 0.25) << "the second pose leaves at 0.25 s";
    // The progress line would have held the run until 1 s.
    EXPECT_LT(wall, 0.9) << run.report << run.output;
}

}  // namespace
}  // namespace catgs::test
