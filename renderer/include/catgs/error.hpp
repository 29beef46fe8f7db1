// The one exception type of catgs. Its message is the user-facing one-line error: it names
// the input (file, flag or field), the problem, and where it was found.
#pragma once

#include <stdexcept>
#include <string>

namespace catgs {

class Error : public std::runtime_error {
public:
    explicit Error(const std::string& message) : std::runtime_error(message) {}
};

}  // namespace catgs
