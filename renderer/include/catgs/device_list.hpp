// The devices a flag names (catgs-server --gpus, catgs-bench and catgs-render
// --shard-devices): one parser, so every tool reads "all", a count and a list alike.
#pragma once

#include <optional>
#include <string>
#include <vector>

namespace catgs {

/// The device indices `VALUE` of flag `flag` names, in increasing order: "all" (every device
/// present), N (devices 0..N-1) or a comma-separated list of distinct indices ("0,2").
/// `present`: the devices there are (CUDA: catgs::device_count), or nullopt where they are
/// simulated (the CPU backend), where "all" is one device (the host) and N goes up to
/// `simulated_limit`. Throws catgs::Error whose message starts "<flag>: ", naming the value or
/// the device at fault.
std::vector<int> parse_device_list(const std::string& flag, const std::string& value, std::optional<int> present,
                                   int simulated_limit);

}  // namespace catgs
