// The "builtin:NAME?key=value&..." syntax, shared by the scene generator (builtin_city.cpp)
// and the procedural flights (trajectory_flights.cpp), so that both accept and refuse the
// same specs with the same words.
#include "catgs/builtin_spec.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <string_view>

#include "catgs/error.hpp"

namespace catgs::detail {

namespace {

constexpr std::string_view kBuiltinPrefix = "builtin:";

// Integers written as 2e6 are accepted; above 2^53 a double no longer holds every integer,
// so the scientific form is refused there (plain digits still reach 2^64 - 1).
constexpr double kMaxExactInteger = 9007199254740992.0;

std::string join(const std::vector<std::string>& items) {
    std::string out;
    for (const auto& item : items) out += (out.empty() ? "" : ", ") + item;
    return out;
}

}  // namespace

std::string builtin_name(const std::string& spec) {
    if (spec.rfind(kBuiltinPrefix, 0) != 0)
        throw Error(spec + ": not a builtin spec (expected builtin:NAME?key=value&...)");
    const std::size_t query = spec.find('?');
    std::string name = spec.substr(kBuiltinPrefix.size(),
                                   query == std::string::npos ? std::string::npos : query - kBuiltinPrefix.size());
    if (name.empty()) throw Error(spec + ": missing a name after 'builtin:'");
    return name;
}

SpecParams builtin_params(const std::string& spec, const std::vector<std::string>& known_keys) {
    SpecParams params;
    std::size_t begin = spec.find('?');
    if (begin == std::string::npos) return params;
    for (++begin;;) {
        const std::size_t end = std::min(spec.find('&', begin), spec.size());
        const std::string item = spec.substr(begin, end - begin);
        const std::size_t eq = item.find('=');
        if (item.empty()) throw Error(spec + ": empty parameter (a stray '?' or '&')");
        if (eq == std::string::npos)
            throw Error(spec + ": parameter '" + item + "' is missing '=' (expected key=value)");
        std::string key = item.substr(0, eq), value = item.substr(eq + 1);
        if (std::find(known_keys.begin(), known_keys.end(), key) == known_keys.end())
            throw Error(spec + ": unknown key '" + key + "' (available: " + join(known_keys) + ")");
        if (value.empty()) throw Error(spec + ": key '" + key + "' has an empty value");
        for (const auto& seen : params)
            if (seen.first == key) throw Error(spec + ": duplicate key '" + key + "'");
        params.emplace_back(std::move(key), std::move(value));
        if (end == spec.size()) return params;
        begin = end + 1;
    }
}

std::uint64_t spec_integer(const std::string& spec, const std::string& key, const std::string& value) {
    const char* first = value.data();
    const char* last = first + value.size();
    std::uint64_t integer = 0;
    if (auto [end, ec] = std::from_chars(first, last, integer); ec == std::errc() && end == last) return integer;
    double real = 0;
    if (auto [end, ec] = std::from_chars(first, last, real);
        ec == std::errc() && end == last && real >= 0 && real <= kMaxExactInteger && real == std::floor(real))
        return static_cast<std::uint64_t>(real);
    throw Error(spec + ": value '" + value + "' of '" + key + "' is not a non-negative integer");
}

double spec_number(const std::string& spec, const std::string& key, const std::string& value) {
    const char* first = value.data();
    const char* last = first + value.size();
    double real = 0;
    if (auto [end, ec] = std::from_chars(first, last, real); ec == std::errc() && end == last && std::isfinite(real))
        return real;
    throw Error(spec + ": value '" + value + "' of '" + key + "' is not a finite number");
}

}  // namespace catgs::detail
