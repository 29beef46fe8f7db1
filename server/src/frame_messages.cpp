#include "catgs/server/frame_messages.hpp"

#include "catgs/server/encoder.hpp"

namespace catgs::server {

double ms_between(TimePoint a, TimePoint b) {
    return std::chrono::duration<double, std::milli>(b - a).count();
}

std::string image_size(const Intrinsics& intrinsics) {
    return std::to_string(intrinsics.width) + "x" + std::to_string(intrinsics.height);
}

namespace {

// What every image frame states about itself: the request it answers and the image's shape.
v1::Frame frame_header(const FrameSetup& request, Format format, int width, int height) {
    v1::Frame frame;
    frame.set_sequence(request.sequence);
    frame.set_encoding(to_proto(format));
    frame.set_width(static_cast<std::uint32_t>(width));
    frame.set_height(static_cast<std::uint32_t>(height));
    frame.set_client_timestamp_us(request.client_timestamp_us);
    return frame;
}

}  // namespace

v1::Frame rendered_frame(const FrameSetup& request, Format format, const ImageRGB8& image, const FrameStats& stats,
                         const RenderTimes& times) {
    v1::Frame frame = frame_header(request, format, image.width, image.height);
    auto* timings = frame.mutable_timings();
    timings->set_queue_ms(ms_between(times.received, times.begin));
    timings->set_render_ms(ms_between(times.begin, times.rendered));
    auto* cache = frame.mutable_cache();
    cache->set_key_frame(stats.key_frame);
    cache->set_window(static_cast<std::uint32_t>(stats.window));
    cache->set_render_length(stats.pairs);
    cache->set_visible(stats.visible);
    cache->set_split_k(stats.split_k);
    return frame;
}

grpc::Status encode_frame(const ImageRGB8& image, const EncodeSettings& settings, TimePoint received,
                          v1::Frame& frame) {
    const TimePoint start = std::chrono::steady_clock::now();
    grpc::Status status;
    try {
        encode_image(image, settings, *frame.mutable_data());
    } catch (const std::exception& e) {
        frame.clear_data();
        status = {grpc::StatusCode::INTERNAL, std::string("encoding failed: ") + e.what()};
    }
    const TimePoint done = std::chrono::steady_clock::now();
    frame.mutable_timings()->set_encode_ms(ms_between(start, done));
    frame.mutable_timings()->set_total_ms(ms_between(received, done));
    return status;
}

v1::Frame resent_frame(const FrameSetup& request, Format format, const Intrinsics& intrinsics, TimePoint received,
                       std::string data) {
    v1::Frame frame = frame_header(request, format, intrinsics.width, intrinsics.height);
    *frame.mutable_data() = std::move(data);
    const TimePoint now = std::chrono::steady_clock::now();
    frame.mutable_timings()->set_queue_ms(ms_between(received, now));
    frame.mutable_timings()->set_total_ms(ms_between(received, now));
    frame.mutable_cache()->set_reused_previous(true);
    return frame;
}

v1::Frame error_frame(std::uint64_t sequence, const grpc::Status& status) {
    v1::Frame frame;
    frame.set_sequence(sequence);
    frame.mutable_error()->set_code(static_cast<int>(status.error_code()));
    frame.mutable_error()->set_message(status.error_message());
    return frame;
}

grpc::Status render_failure_status(const RenderFailure& failure, const std::string& size) {
    if (!failure.out_of_memory) return {grpc::StatusCode::INTERNAL, "render failed: " + failure.what};
    const std::string what = size.empty() ? "the render failed" : "rendering at " + size + " failed";
    return {grpc::StatusCode::RESOURCE_EXHAUSTED, "out-of-memory: " + what + " (" + failure.what +
                                                      "); lower the resolution, retry later or use another server"};
}

grpc::Status renderer_failure_status(const RenderFailure& failure, const std::string& scene_id) {
    if (!failure.out_of_memory) return {grpc::StatusCode::INTERNAL, "cannot create a renderer: " + failure.what};
    return {grpc::StatusCode::RESOURCE_EXHAUSTED, "out-of-memory: the server cannot hold scene '" + scene_id +
                                                      "' for another session (" + failure.what +
                                                      "); retry later or on another server"};
}

grpc::Status session_memory_status(const std::string& scene_id, const std::string& size, std::uint64_t needed,
                                   std::uint64_t allowed) {
    return {grpc::StatusCode::RESOURCE_EXHAUSTED,
            "max-session-memory: rendering scene '" + scene_id + "'" + (size.empty() ? "" : " at " + size) +
                " needed " + std::to_string(needed) + " bytes of renderer memory; this server allows " +
                std::to_string(allowed) + " per session; lower the resolution"};
}

}  // namespace catgs::server
