// rasterize, the per-pixel blend of graphdeco 3DGS (paper eq. 3): front to back,
// C += c * alpha * T, T *= 1 - alpha, with alpha = min(0.99, sigma * exp(-q/2)).
#pragma once

#include <cstdint>

#include "catgs/constants.hpp"
#include "catgs/hd.hpp"
#include "catgs/math.hpp"

namespace catgs {

template <typename T>
struct PixelAccumulator {
    Vec3<T> colour{T(0), T(0), T(0)};
    T transmittance = T(1);
    bool done = false;
};

/// The exponent -q/2 of the Gaussian at (px, py) (paper eq. 4 with the 2D conic).
template <typename T>
CATGS_INLINE T gaussian_power(Vec2<T> mean, Vec3<T> conic, T px, T py) {
    const T dx = mean.x - px, dy = mean.y - py;
    return T(-0.5) * (conic.x * dx * dx + conic.z * dy * dy) - conic.y * dx * dy;
}

/// The smallest power at which a Gaussian of this opacity reaches alpha = 1/255: below it
/// blend_power draws nothing, so a rasterizer may skip the exp (+inf for opacity 0).
template <typename T>
CATGS_INLINE T min_visible_power(T opacity) {
    return log_of(static_cast<T>(kMinAlpha) / opacity);
}

/// graphdeco's alpha, min(0.99, opacity * exp(power)), and whether the Gaussian shows at all:
/// power <= 0 and the unclamped alpha >= 1/255.
template <typename T>
struct BlendAlpha {
    T alpha;
    bool visible;
};
/// The clamp and the two tests of blend_alpha, on an alpha already taken: `in_front` is the
/// exponent's power <= 0 in whatever form the caller computed it.
template <typename T>
CATGS_HD BlendAlpha<T> clamp_alpha(T raw_alpha, bool in_front) {
    // Written so that NaN fails both tests: far off-screen means can make the quadratic form
    // inf - inf, and min(0.99, NaN) would otherwise draw a NaN alpha as 0.99. `&` rather than
    // `&&`: every operand is a comparison already made, nothing to short-circuit.
    const bool visible = in_front & (raw_alpha >= static_cast<T>(kMinAlpha));
    return {raw_alpha < static_cast<T>(kMaxAlpha) ? raw_alpha : static_cast<T>(kMaxAlpha), visible};
}

template <typename T, typename ExpFn>
CATGS_HD BlendAlpha<T> blend_alpha(T power, T opacity, ExpFn exp_fn) {
    return clamp_alpha(opacity * exp_fn(power), power <= T(0));
}

/// blend_alpha in base 2 with the opacity folded into the exponent, as the CUDA float
/// rasterizer stages it: `folded` = log2(e) * power + log2(opacity), so that alpha is one exp2
/// and no multiply. power <= 0 reads folded <= log2(opacity). Opacity 0 (log2 = -inf) draws
/// nothing; a NaN exponent fails both tests, as in blend_alpha.
template <typename T, typename Exp2Fn>
CATGS_HD BlendAlpha<T> blend_alpha_folded(T folded, T log2_opacity, Exp2Fn exp2_fn) {
    return clamp_alpha(exp2_fn(folded), folded <= log2_opacity);
}

/// blend_gaussian with the power already computed, alpha's exponential taken by `exp_fn` (the
/// CUDA float rasterizer passes the hardware's, see rasterize.cu), and nothing blended once
/// acc.done. Straight-line code: the tests are predicates on what is written, not branches
/// around it, so that a GPU warp whose pixels disagree issues one path, not several (the
/// rasterizer is bound by the instructions it issues). The exponential is always taken; a
/// caller that wants to skip it tests min_visible_power first.
template <typename T, typename ExpFn>
CATGS_HD void blend_power_unless_done(PixelAccumulator<T>& acc, T power, T opacity, Vec3<T> colour, T min_transmittance,
                                      ExpFn exp_fn) {
    const BlendAlpha<T> a = blend_alpha(power, opacity, exp_fn);
    const bool draws = !acc.done & a.visible;
    const T alpha = a.alpha;
    // T(1 - alpha) written as T - alpha T: the product is the colour's weight too, one
    // multiply a pixel and Gaussian fewer on the GPU (the rounding moves by an ulp of T).
    const T weight = alpha * acc.transmittance;
    const T next = acc.transmittance - weight;
    // graphdeco's exclusive stop: the Gaussian that would bring T below the threshold is not
    // drawn, and the pixel is done.
    const bool stops = draws & (next < min_transmittance);
    acc.done = acc.done | stops;
    if (draws & !stops) {
        acc.colour = {acc.colour.x + colour.x * weight, acc.colour.y + colour.y * weight,
                      acc.colour.z + colour.z * weight};
        acc.transmittance = next;
    }
}

/// A pixel whose stop is the sign of its transmittance: negative once done, its magnitude the
/// transmittance it stopped at. The CUDA rasterizer's accumulator: a separate done flag cost it
/// six instructions a pixel and Gaussian to keep (a bool in a register, masked and re-tested),
/// about a fifth of its blend (ncu, city_ring 4K, H200, 2026-12-04).
template <typename T>
struct SignedPixel {
    Vec3<T> colour{T(0), T(0), T(0)};
    T signed_transmittance = T(1);

    /// A pixel to draw, or (outside the image) one that is done before it starts.
    CATGS_HD static SignedPixel starting(bool drawn) {
        SignedPixel p;
        p.signed_transmittance = drawn ? T(1) : T(-1);
        return p;
    }
    CATGS_HD bool done() const { return signed_transmittance < T(0); }
    /// The same pixel as blend_power_unless_done leaves it.
    CATGS_HD PixelAccumulator<T> accumulator() const {
        PixelAccumulator<T> acc;
        acc.colour = colour;
        acc.transmittance = fabs_of(signed_transmittance);
        acc.done = done();
        return acc;
    }
};

/// blend_power_unless_done on a SignedPixel: the same colour, transmittance and stop for any
/// min_transmittance >= 0. A done pixel's transmittance is negative, so its next transmittance
/// is below any such threshold: it "stops" again, which writes nothing but the sign, and the
/// done test needs no operand of its own. A stop negates a transmittance >= the threshold, or
/// the starting 1, so it never reaches 0 (where -0 would read as not done).
template <typename T>
CATGS_HD void blend_signed(SignedPixel<T>& px, BlendAlpha<T> a, Vec3<T> colour, T min_transmittance) {
    const bool visible = a.visible;
    const T alpha = a.alpha;
    const T t = px.signed_transmittance;
    const T weight = alpha * t;  // shared with next, as in blend_power_unless_done
    const T next = t - weight;
    const bool stops = visible & (next < min_transmittance);
    const bool draws = visible & !stops;
    if (draws)
        px.colour = {px.colour.x + colour.x * weight, px.colour.y + colour.y * weight, px.colour.z + colour.z * weight};
    // One select after the other, on the same value: as two guarded assignments ptxas kept the
    // old and the new transmittance in two registers and copied between them, three moves a
    // pixel and Gaussian (SASS, H100, 2026-12-06). t is never 0 or NaN at a stop: one FADD.
    const T kept = stops ? -fabs_of(t) : t;
    px.signed_transmittance = draws ? next : kept;
}

/// blend_signed with alpha from the power (blend_alpha).
template <typename T, typename ExpFn>
CATGS_HD void blend_power_signed(SignedPixel<T>& px, T power, T opacity, Vec3<T> colour, T min_transmittance,
                                 ExpFn exp_fn) {
    blend_signed(px, blend_alpha(power, opacity, exp_fn), colour, min_transmittance);
}

/// blend_power_unless_done on a pixel not yet done; returns true when this Gaussian stopped it.
template <typename T, typename ExpFn>
CATGS_HD bool blend_power_with(PixelAccumulator<T>& acc, T power, T opacity, Vec3<T> colour, T min_transmittance,
                               ExpFn exp_fn) {
    blend_power_unless_done(acc, power, opacity, colour, min_transmittance, exp_fn);
    return acc.done;
}

/// blend_gaussian with the power already computed.
template <typename T>
CATGS_HD bool blend_power(PixelAccumulator<T>& acc, T power, T opacity, Vec3<T> colour,
                          T min_transmittance = static_cast<T>(kMinTransmittance)) {
    return blend_power_with(acc, power, opacity, colour, min_transmittance, [](T v) { return exp_of(v); });
}

/// Blends one Gaussian into a pixel sampled at (px, py). Sets acc.done (and blends nothing)
/// when this Gaussian would bring the transmittance below `min_transmittance`: graphdeco's
/// exclusive stop. Returns acc.done.
template <typename T>
CATGS_HD bool blend_gaussian(PixelAccumulator<T>& acc, Vec2<T> mean, Vec3<T> conic, T opacity, Vec3<T> colour, T px,
                             T py, T min_transmittance = static_cast<T>(kMinTransmittance)) {
    return blend_power(acc, gaussian_power(mean, conic, px, py), opacity, colour, min_transmittance);
}

/// Final pixel value C + T * background, before clamping.
template <typename T>
CATGS_INLINE Vec3<T> finish_pixel(const PixelAccumulator<T>& acc, Vec3<T> background) {
    return {acc.colour.x + acc.transmittance * background.x, acc.colour.y + acc.transmittance * background.y,
            acc.colour.z + acc.transmittance * background.z};
}

/// Clamps to [0, 1] and rounds to the nearest 8-bit level.
template <typename T>
CATGS_INLINE std::uint8_t quantize_8bit(T v) {
    v = v > T(0) ? (v < T(1) ? v : T(1)) : T(0);  // NaN -> 0
    return static_cast<std::uint8_t>(v * T(255) + T(0.5));
}

}  // namespace catgs
