// The command-line protocol every catgs executable follows, written once: --help prints and
// exits 0; a bad flag, or input that throws catgs::Error, prints one line "<tool>: <why>" and
// exits kExitBadInput; any other exception prints "<tool>: failed: <why>" and exits
// kExitFailure (exit_codes.hpp).
#pragma once

#include <CLI/CLI.hpp>

#include <functional>
#include <optional>

namespace catgs {

/// Parses argv into `app`. nullopt: parsed, go on; otherwise the exit status (help was
/// printed, or the one-line error).
std::optional<int> parse_command_line(CLI::App& app, int argc, char** argv, const char* tool);

/// Runs `body` and turns what it throws into the one-line error and the exit status above.
int run_reporting_errors(const char* tool, const std::function<int()>& body);

// Flag values checked as they are parsed, before a scene loads or a connection opens, by
// every tool that takes them.

/// --width and --height: 1..kMaxImageSide.
CLI::Validator image_side();

/// --fov, the horizontal field of view in degrees: kMinFieldOfViewDegrees..kMaxFieldOfViewDegrees,
/// the protocol's range (at 180 the focal length is 0).
CLI::Validator horizontal_fov();

/// --quality, JPEG quality: 1..100, as libjpeg-turbo and the protocol take it.
CLI::Validator jpeg_quality();

/// A number in [lo, hi]; NaN is refused too (CLI::Range lets it through). `unit` names the
/// number in --help and in the message.
CLI::Validator bounded_number(double lo, double hi, const std::string& unit);

/// A flag counting threads: 0 (as many as the host has cores) to kMaxThreads, checked as it is
/// parsed.
CLI::Validator thread_count();

/// parse_command_line, then run_reporting_errors: the whole of most tools' main().
int run_command_line(CLI::App& app, int argc, char** argv, const char* tool, const std::function<int()>& body);

}  // namespace catgs
