// The parsers and names of the options' free-text values, shared by the tools, the client
// and the server.
#include "catgs/render_options.hpp"

#include <stdexcept>

#include "catgs/error.hpp"

namespace catgs {

Culling parse_culling(const std::string& name) {
    if (name == "exact") return Culling::exact;
    if (name == "bbox3sigma") return Culling::bbox3sigma;
    if (name == "opacity-aware") return Culling::opacity_aware;
    throw Error("unknown culling mode '" + name + "' (expected exact, bbox3sigma or opacity-aware)");
}

std::optional<std::uint32_t> parse_split_k(const std::string& text) {
    try {
        std::size_t used = 0;
        const long k = std::stol(text, &used);
        if (used == text.size() && k >= 1 && k <= static_cast<long>(kMaxSplitK)) return static_cast<std::uint32_t>(k);
    } catch (const std::logic_error&) {
    }
    return std::nullopt;
}

std::optional<double> parse_degrees(const std::string& text) {
    try {
        std::size_t used = 0;
        const double degrees = std::stod(text, &used);
        if (used == text.size() && degrees >= 0 && degrees <= 180) return degrees;
    } catch (const std::logic_error&) {
    }
    return std::nullopt;
}

const char* culling_name(Culling culling) {
    switch (culling) {
        case Culling::exact:
            return "exact";
        case Culling::bbox3sigma:
            return "bbox3sigma";
        case Culling::opacity_aware:
            return "opacity-aware";
    }
    return "?";
}

}  // namespace catgs
