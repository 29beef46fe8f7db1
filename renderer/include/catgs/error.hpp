// The exception type of catgs. Its message is the user-facing one-line error: it names the
// input (file, flag or field), the problem, and where it was found.
#pragma once

#include <sstream>
#include <stdexcept>
#include <string>

namespace catgs {

class Error : public std::runtime_error {
public:
    explicit Error(const std::string& message) : std::runtime_error(message) {}
};

/// Device memory ran out. Unlike other errors the request may succeed later or smaller, and
/// the server ends the session (freeing its buffers) instead of answering one frame.
class OutOfMemoryError : public Error {
public:
    using Error::Error;
};

/// A limit the caller set (LoadOptions::max_records, max_scene_bytes) refused the input,
/// which may be valid: a server answers RESOURCE_EXHAUSTED, not INVALID_ARGUMENT.
class LimitError : public Error {
public:
    using Error::Error;
};

/// A number in a message as a person writes it (1e+30, 0.001, 179.9), not std::to_string's
/// six fixed decimals (0.000000 for 1e-30).
inline std::string format_number(double value) {
    std::ostringstream s;
    s << value;
    return s.str();
}

}  // namespace catgs
