// Turns protocol messages into renderer inputs, validating every field. Errors are
// INVALID_ARGUMENT with a message that starts with the field's path (e.g. "open.width: ...")
// or RESOURCE_EXHAUSTED naming the server limit. Pure functions: the tests use them to build
// the same RenderOptions and cameras the server uses.
#pragma once

#include <grpcpp/support/status.h>

#include <cstdint>
#include <optional>
#include <string>

#include "catgs/cache.hpp"
#include "catgs/camera.hpp"
#include "catgs/render_options.hpp"
#include "catgs/server/admission.hpp"
#include "catgs/server/encoder.hpp"
#include "catgs/v1/catgs.pb.h"

namespace catgs::server {

/// Images larger than this in either dimension are malformed requests (INVALID_ARGUMENT),
/// whatever the server's configured limit (which gives RESOURCE_EXHAUSTED below it).
inline constexpr std::uint32_t kMaxProtocolDimension = kMaxImageSide;
/// Flight plans longer than the largest speculation window are of no use to the renderer.
inline constexpr int kMaxFlightPlanPoses = kMaxWindow;
/// SessionConfig.client_name goes into log lines: longer names, and names with control
/// characters, are malformed requests.
inline constexpr std::size_t kMaxClientNameLength = 256;
/// C0 control bytes and DEL: what a log line must never carry raw from a client (a newline
/// forges a line, an escape sequence hides one). Client names with them are refused, scene
/// ids are echoed with them escaped.
constexpr bool is_control_byte(unsigned char byte) {
    return byte < 0x20 || byte == 0x7f;
}
/// Pose positions further out are malformed: the scene loaders' bound on stored coordinates
/// (kMaxAbsCoordinate, renderer/src/scene_io_detail.cpp), so no scene reaches that far, and
/// far enough inside double range that a camera's translation stays finite.
inline constexpr double kMaxAbsPosition = 1e30;
/// Server-side defaults for fields left at zero.
inline constexpr int kDefaultJpegQuality = 85;
inline constexpr double kDefaultHorizontalFovDegrees = 70.0;
inline constexpr int kDefaultMaxUnackedFrames = 2;
inline constexpr int kMaxUnackedFramesLimit = 2;

/// INVALID_ARGUMENT naming the first enum field of `message`, at any depth (e.g.
/// "open.pipeline.cache"), whose value its enum does not define; OK otherwise. Proto3 enums
/// are open: the parser keeps an unknown number in the field, and a switch over the known
/// values would silently take its default. Walked through the descriptors, so fields added to
/// the protocol later are checked without code here. `prefix` starts every path ("": none).
grpc::Status check_enum_values(const google::protobuf::Message& message, const std::string& prefix);

struct SessionSetup {
    std::string scene_id;
    Intrinsics intrinsics;
    RenderOptions options;
    EncodeSettings encode;
    int max_unacked_frames = kDefaultMaxUnackedFrames;
};

/// Validates an opening message (`prefix` is "open" for Stream, "config" for Render).
grpc::Status parse_session_config(const v1::SessionConfig& config, const Limits& limits, const std::string& prefix,
                                  SessionSetup* out);

/// The RenderOptions a session with this (valid) configuration renders with.
RenderOptions render_options_for(const v1::PipelineOptions& pipeline, const v1::Color* background);

struct FrameSetup {
    std::uint64_t sequence = 0;
    std::int64_t client_timestamp_us = 0;
    std::uint64_t last_received_sequence = 0;
    Camera camera;
    std::optional<FrameHints> hints;  ///< set when the request carries velocity or a plan
};

/// INVALID_ARGUMENT when the flight plan is longer than kMaxFlightPlanPoses. Cheap: callers
/// run it before check_enum_values, whose walk over every element a long plan makes costly.
grpc::Status check_flight_plan_length(const v1::FrameRequest& request, const std::string& prefix);

/// Validates a frame request against the session's intrinsics (`prefix`: "frame").
grpc::Status parse_frame_request(const v1::FrameRequest& request, const Intrinsics& intrinsics,
                                 const std::string& prefix, FrameSetup* out);

/// The camera a pose describes (validated by parse_frame_request).
Camera camera_from_pose(const v1::Pose& pose, const Intrinsics& intrinsics, std::int64_t client_timestamp_us);

v1::Encoding to_proto(Format format);

}  // namespace catgs::server
