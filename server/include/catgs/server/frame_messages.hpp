// What a render ends in, for RenderService.Render (services.cpp) and RenderService.Stream
// (stream_session.cpp) alike: the frame of a rendered image and its encoding, and the status
// of a render that failed. Both paths build them here so that they answer the same way.
#pragma once

#include <grpcpp/support/status.h>

#include <chrono>
#include <cstdint>
#include <exception>
#include <new>
#include <optional>
#include <string>

#include "catgs/error.hpp"
#include "catgs/image.hpp"
#include "catgs/render_options.hpp"
#include "catgs/server/request_validation.hpp"
#include "catgs/v1/catgs.pb.h"

namespace catgs::server {

using TimePoint = std::chrono::steady_clock::time_point;

double ms_between(TimePoint a, TimePoint b);
/// "WIDTHxHEIGHT", as messages name an image size.
std::string image_size(const Intrinsics& intrinsics);

/// When a frame's request arrived, and when its render began and ended.
struct RenderTimes {
    TimePoint received, begin, rendered;
};

/// The frame of a rendered `image`, not yet encoded: the request's sequence and timestamp,
/// the image's encoding and size, queue and render times, and the cache statistics.
v1::Frame rendered_frame(const FrameSetup& request, Format format, const ImageRGB8& image, const FrameStats& stats,
                         const RenderTimes& times);
/// Encodes `image` into frame.data and sets the encode and total times. When the encoder
/// fails, frame.data is empty and the status is INTERNAL "encoding failed: ...".
grpc::Status encode_frame(const ImageRGB8& image, const EncodeSettings& settings, TimePoint received, v1::Frame& frame);
/// A repeated pose answered with `data`, the last frame's bytes (a session's size and encoding
/// are fixed, so the same pose is the same frame): marked reused_previous, never rendered.
v1::Frame resent_frame(const FrameSetup& request, Format format, const Intrinsics& intrinsics, TimePoint received,
                       std::string data);
/// A frame that answers request `sequence` with `status` instead of an image.
v1::Frame error_frame(std::uint64_t sequence, const grpc::Status& status);

/// What a renderer threw. Memory running out is told apart by type: catgs::OutOfMemoryError
/// (the CUDA backend) or std::bad_alloc (the CPU backend, any host allocation).
struct RenderFailure {
    bool out_of_memory = false;
    std::string what;  ///< never empty
};

/// Runs `render`; the failure, if it threw.
template <typename Render>
std::optional<RenderFailure> catch_render_failure(Render&& render) {
    const auto failure = [](bool out_of_memory, const std::exception& e) {
        std::string what = e.what();
        return RenderFailure{out_of_memory, what.empty() ? "unknown error" : std::move(what)};
    };
    try {
        render();
    } catch (const OutOfMemoryError& e) {
        return failure(true, e);
    } catch (const std::bad_alloc& e) {
        return failure(true, e);
    } catch (const std::exception& e) {
        return failure(false, e);
    }
    return std::nullopt;
}

/// A failed render: RESOURCE_EXHAUSTED "out-of-memory: ..." when memory ran out, else
/// INTERNAL "render failed: ...". `size` (image_size) is named in streams; unary calls pass "".
grpc::Status render_failure_status(const RenderFailure& failure, const std::string& size);
/// A failure to make a session's renderer: putting `scene_id` on the device ran out of memory
/// (RESOURCE_EXHAUSTED "out-of-memory: ..."), or INTERNAL "cannot create a renderer: ...".
grpc::Status renderer_failure_status(const RenderFailure& failure, const std::string& scene_id);
/// A render that needed `needed` bytes of renderer memory, more than Limits::max_session_bytes
/// (`allowed`): RESOURCE_EXHAUSTED "max-session-memory: ...". `size` as above.
grpc::Status session_memory_status(const std::string& scene_id, const std::string& size, std::uint64_t needed,
                                   std::uint64_t allowed);

}  // namespace catgs::server
