#include "catgs/device_list.hpp"

#include <algorithm>
#include <charconv>

#include "catgs/error.hpp"

namespace catgs {
namespace {

/// A non-negative decimal integer, every character a digit; nullopt otherwise (signs, spaces,
/// overflow, empty).
std::optional<int> parse_index(const std::string& text) {
    if (text.empty() || !std::all_of(text.begin(), text.end(), [](char c) { return c >= '0' && c <= '9'; }))
        return std::nullopt;
    int value = 0;
    const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
    if (error != std::errc() || end != text.data() + text.size()) return std::nullopt;
    return value;
}

std::string present_text(int present) {
    if (present == 0) return "no CUDA device is present";
    return std::to_string(present) + " CUDA device" + (present == 1 ? " is" : "s are") + " present (0.." +
           std::to_string(present - 1) + ")";
}

[[noreturn]] void bad_list(const std::string& flag, const std::string& value, const std::string& problem) {
    throw Error(flag + ": '" + value + "': " + problem);
}

}  // namespace

std::vector<int> parse_device_list(const std::string& flag, const std::string& value, std::optional<int> present,
                                   int simulated_limit) {
    const std::string expected = "expected all, a device count N or a comma-separated list of device indices (0,2)";
    if (value.empty()) bad_list(flag, value, "empty; " + expected);
    const int limit = present ? *present : simulated_limit;
    const std::string limit_text =
        present ? present_text(*present) : "the CPU backend simulates at most " + std::to_string(limit) + " devices";
    std::vector<int> devices;
    if (value == "all") {
        if (present && *present == 0) bad_list(flag, value, present_text(0));
        // The CPU backend has one real device, the host: more are simulated only when asked for.
        const int count = present ? *present : 1;
        for (int d = 0; d < count; ++d) devices.push_back(d);
        return devices;
    }
    if (value.find(',') == std::string::npos) {
        const std::optional<int> count = parse_index(value);
        if (!count) bad_list(flag, value, expected);
        if (*count == 0) bad_list(flag, value, "a device count must be at least 1");
        if (*count > limit) bad_list(flag, value, std::to_string(*count) + " devices asked for, but " + limit_text);
        for (int d = 0; d < *count; ++d) devices.push_back(d);
        return devices;
    }
    std::size_t begin = 0;
    while (begin <= value.size()) {
        const std::size_t end = std::min(value.find(',', begin), value.size());
        const std::string item = value.substr(begin, end - begin);
        const std::optional<int> index = parse_index(item);
        if (!index) bad_list(flag, value, "'" + item + "' is not a device index; " + expected);
        if (*index >= limit) bad_list(flag, value, "device " + item + " does not exist: " + limit_text);
        if (std::find(devices.begin(), devices.end(), *index) != devices.end())
            bad_list(flag, value, "device " + item + " is named twice");
        devices.push_back(*index);
        begin = end + 1;
    }
    std::sort(devices.begin(), devices.end());
    return devices;
}

}  // namespace catgs
