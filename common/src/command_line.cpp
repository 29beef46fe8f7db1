#include "catgs/common/command_line.hpp"

#include <exception>
#include <iostream>

#include "catgs/common/exit_codes.hpp"
#include "catgs/error.hpp"
#include "catgs/parallel.hpp"

namespace catgs {

std::optional<int> parse_command_line(CLI::App& app, int argc, char** argv, const char* tool) {
    try {
        app.parse(argc, argv);
    } catch (const CLI::CallForHelp& e) {
        return app.exit(e);
    } catch (const CLI::CallForAllHelp& e) {
        return app.exit(e);
    } catch (const CLI::ParseError& e) {
        std::cerr << tool << ": " << e.what() << "\n";
        return kExitBadInput;
    }
    return std::nullopt;
}

CLI::Validator thread_count() {
    return CLI::Range(0, kMaxThreads);
}

int run_reporting_errors(const char* tool, const std::function<int()>& body) {
    try {
        return body();
    } catch (const Error& e) {
        std::cerr << tool << ": " << e.what() << "\n";
        return kExitBadInput;
    } catch (const std::exception& e) {
        std::cerr << tool << ": failed: " << e.what() << "\n";
        return kExitFailure;
    }
}

int run_command_line(CLI::App& app, int argc, char** argv, const char* tool, const std::function<int()>& body) {
    if (const std::optional<int> status = parse_command_line(app, argc, argv, tool)) return *status;
    return run_reporting_errors(tool, body);
}

}  // namespace catgs
