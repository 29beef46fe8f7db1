// libFuzzer target: the "builtin:NAME?key=value&..." parser shared by scene generators and
// flights (builtin_spec.hpp) and the city spec on top of it (parse_city_spec). Nothing is
// generated: a valid city spec is only checked against its documented range.

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>

#include "catgs/builtin_city.hpp"
#include "catgs/builtin_spec.hpp"
#include "catgs/error.hpp"
#include "fuzz_util.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    if (size > 4096) return -1;
    const std::string spec = catgs::fuzz::as_string(data, size);
    using catgs::fuzz::require;
    try {
        const catgs::CityParams city = catgs::parse_city_spec(spec);
        require(city.gaussians >= catgs::kCityMinGaussians && city.gaussians <= catgs::kCityMaxGaussians,
                "city spec accepted with an out-of-range count");
    } catch (const catgs::Error&) {
        // Spec errors quote the spec as given (a NUL in it cuts what() short): any message.
    }
    try {
        const std::string name = catgs::detail::builtin_name(spec);
        require(!name.empty() && name.find('?') == std::string::npos, "bad builtin name '" + name + "'");
        const auto params = catgs::detail::builtin_params(spec, {"gaussians", "seed", "speed", "x", ""});
        for (const auto& [key, value] : params) {
            require(!value.empty(), "empty value accepted");
            try {
                (void)catgs::detail::spec_integer(spec, key, value);
            } catch (const catgs::Error&) {
            }
            try {
                const double v = catgs::detail::spec_number(spec, key, value);
                require(std::isfinite(v), "spec_number returned a non-finite value");
            } catch (const catgs::Error&) {
            }
        }
    } catch (const catgs::Error&) {
        // Spec errors quote the spec as given (a NUL in it cuts what() short): any message.
    }
    return 0;
}
