// The "builtin:NAME?key=value&..." syntax shared by scene generators and procedural camera
// paths. Every error is a catgs::Error that quotes the spec and names the bad part.
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace catgs::detail {

using SpecParams = std::vector<std::pair<std::string, std::string>>;

/// NAME of "builtin:NAME?...".
std::string builtin_name(const std::string& spec);
/// The key=value pairs, each key at most once and one of `known_keys`.
SpecParams builtin_params(const std::string& spec, const std::vector<std::string>& known_keys);
/// A non-negative integer value (also written as 2e6); the error names the key.
std::uint64_t spec_integer(const std::string& spec, const std::string& key, const std::string& value);
/// A finite number; the error names the key.
double spec_number(const std::string& spec, const std::string& key, const std::string& value);

}  // namespace catgs::detail
