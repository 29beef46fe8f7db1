#include "catgs/common/command_line.hpp"

#include <exception>
#include <iostream>

#include "catgs/common/exit_codes.hpp"
#include "catgs/constants.hpp"
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

CLI::Validator image_side() {
    return CLI::Range(1, kMaxImageSide);
}

CLI::Validator bounded_number(double lo, double hi, const std::string& unit) {
    const std::string range = "[" + CLI::detail::to_string(lo) + ", " + CLI::detail::to_string(hi) + "]";
    return CLI::Validator(
        [lo, hi, unit, range](std::string& text) -> std::string {
            double value = 0;
            if (CLI::detail::lexical_cast(text, value) && value >= lo && value <= hi) return {};
            return "expected " + unit + " in " + range + ", not " + text;
        },
        unit + " in " + range);
}

CLI::Validator horizontal_fov() {
    return bounded_number(kMinFieldOfViewDegrees, kMaxFieldOfViewDegrees, "a horizontal field of view in degrees");
}

CLI::Validator jpeg_quality() {
    return CLI::Range(1, 100);
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
