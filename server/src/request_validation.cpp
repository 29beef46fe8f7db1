#include "catgs/server/request_validation.hpp"

#include <google/protobuf/descriptor.h>
#include <google/protobuf/message.h>

#include <cmath>
#include <cstdio>
#include <sstream>
#include <utility>
#include <vector>

#include "catgs/common/pose_wire.hpp"
#include "catgs/constants.hpp"
#include "catgs/error.hpp"

namespace catgs::server {
namespace {

grpc::Status invalid(const std::string& field, const std::string& problem) {
    return {grpc::StatusCode::INVALID_ARGUMENT, field + ": " + problem};
}

bool finite(const v1::Vec3& v) {
    return std::isfinite(v.x()) && std::isfinite(v.y()) && std::isfinite(v.z());
}

/// Quaternions shorter than this cannot be normalised reliably (and mean a client bug).
constexpr double kMinQuaternionNorm = 1e-6;

grpc::Status check_position(const v1::Vec3& p, const std::string& field) {
    if (!finite(p))
        return invalid(field, "not finite (" + format_number(p.x()) + ", " + format_number(p.y()) + ", " +
                                  format_number(p.z()) + ")");
    static_assert(kMaxAbsPosition == 1e30, "the message below spells the bound as the loaders do");
    for (const auto& [axis, value] : {std::pair{"x", p.x()}, std::pair{"y", p.y()}, std::pair{"z", p.z()}})
        if (std::fabs(value) > kMaxAbsPosition)
            return invalid(field + "." + axis, format_number(value) + " is beyond +-1e30");
    return grpc::Status::OK;
}

grpc::Status check_pose(const v1::Pose& pose, const std::string& field) {
    if (!pose.has_position()) return invalid(field + ".position", "missing");
    if (grpc::Status s = check_position(pose.position(), field + ".position"); !s.ok()) return s;
    if (!pose.has_orientation()) return invalid(field + ".orientation", "missing");
    const auto& q = pose.orientation();
    if (!(std::isfinite(q.w()) && std::isfinite(q.x()) && std::isfinite(q.y()) && std::isfinite(q.z())))
        return invalid(field + ".orientation", "quaternion is not finite");
    const double norm = std::sqrt(q.w() * q.w() + q.x() * q.x() + q.y() * q.y() + q.z() * q.z());
    if (!(norm >= kMinQuaternionNorm)) return invalid(field + ".orientation", "quaternion has zero length");
    return grpc::Status::OK;
}

/// The field of view (degrees) that focal length `f` gives across `size` pixels.
double field_of_view_degrees(double size, double f) {
    return 2.0 * std::atan(size / (2.0 * f)) * 180.0 / kPi;
}

std::string field_of_view_range() {
    std::ostringstream s;  // not "[" + std::string: GCC 12 warns falsely (-Wrestrict) on that
    s << '[' << kMinFieldOfViewDegrees << ", " << kMaxFieldOfViewDegrees << ']';
    return s.str();
}

bool sane_field_of_view(double degrees) {
    return degrees >= kMinFieldOfViewDegrees && degrees <= kMaxFieldOfViewDegrees;
}

// A finite positive double can still become a float infinity or zero in the renderers (e.g.
// fx = 1e300: every Gaussian culled, a blank frame); a sane field of view bounds the focal
// length well inside float range for every protocol image size.
grpc::Status check_focal_length(double f, double size, const std::string& field, const char* direction) {
    if (!(std::isfinite(f) && f > 0)) return invalid(field, format_number(f) + " is not a positive focal length");
    const double fov = field_of_view_degrees(size, f);
    if (!sane_field_of_view(fov))
        return invalid(field, format_number(f) + " gives a " + direction + " field of view of " + format_number(fov) +
                                  " degrees, outside " + field_of_view_range());
    return grpc::Status::OK;
}

grpc::Status parse_intrinsics(const v1::Intrinsics& in, int width, int height, const std::string& prefix,
                              Intrinsics* out) {
    const std::string i = prefix + "intrinsics.";
    if (grpc::Status s = check_focal_length(in.fx(), width, i + "fx", "horizontal"); !s.ok()) return s;
    if (grpc::Status s = check_focal_length(in.fy(), height, i + "fy", "vertical"); !s.ok()) return s;
    if (!(std::isfinite(in.cx()) && in.cx() >= 0 && in.cx() <= width))
        return invalid(i + "cx", "principal point " + format_number(in.cx()) + " is outside the image width 0.." +
                                     std::to_string(width));
    if (!(std::isfinite(in.cy()) && in.cy() >= 0 && in.cy() <= height))
        return invalid(i + "cy", "principal point " + format_number(in.cy()) + " is outside the image height 0.." +
                                     std::to_string(height));
    *out = Intrinsics{in.fx(), in.fy(), in.cx(), in.cy(), width, height};
    return grpc::Status::OK;
}

grpc::Status parse_field_of_view(const v1::SessionConfig& config, int width, int height, const std::string& prefix,
                                 Intrinsics* out) {
    const double fov =
        config.horizontal_fov_degrees() == 0 ? kDefaultHorizontalFovDegrees : config.horizontal_fov_degrees();
    if (!sane_field_of_view(fov))
        return invalid(prefix + "horizontal_fov_degrees", format_number(fov) + " is outside " + field_of_view_range());
    *out = intrinsics_from_fov(width, height, fov);
    return grpc::Status::OK;
}

// Log lines quote it: a newline or an escape sequence would forge or hide lines.
grpc::Status check_client_name(const std::string& name, const std::string& field) {
    if (name.size() > kMaxClientNameLength)
        return invalid(field, std::to_string(name.size()) + " bytes; at most " + std::to_string(kMaxClientNameLength));
    for (std::size_t i = 0; i < name.size(); ++i) {
        const auto byte = static_cast<unsigned char>(name[i]);
        if (is_control_byte(byte)) {
            char hex[8];
            std::snprintf(hex, sizeof hex, "0x%02x", byte);
            return invalid(field, std::string("control character ") + hex + " at byte " + std::to_string(i) +
                                      "; only printable text is accepted");
        }
    }
    return grpc::Status::OK;
}

// Built from a validated pose the translation is finite (|position| <= 1e30); this guards
// the renderers should the pose checks and camera_from_pose ever drift apart.
grpc::Status checked_camera(const v1::Pose& pose, const Intrinsics& intrinsics, std::int64_t client_timestamp_us,
                            const std::string& field, Camera* out) {
    *out = camera_from_pose(pose, intrinsics, client_timestamp_us);
    for (double v : out->pose.translation)
        if (!std::isfinite(v)) return invalid(field, "the camera's translation is not finite");
    return grpc::Status::OK;
}

namespace pb = google::protobuf;

grpc::Status unknown_enum_value(const std::string& field, const pb::EnumDescriptor& type, int value) {
    std::string known;
    for (int i = 0; i < type.value_count(); ++i)
        known += (i ? ", " : "") + std::to_string(type.value(i)->number()) + " " + type.value(i)->name();
    return invalid(field,
                   "unknown value " + std::to_string(value) + " of " + type.full_name() + " (known: " + known + ")");
}

}  // namespace

grpc::Status check_enum_values(const pb::Message& message, const std::string& prefix) {
    const pb::Reflection& reflection = *message.GetReflection();
    std::vector<const pb::FieldDescriptor*> fields;
    reflection.ListFields(message, &fields);  // the fields set; an unset enum holds 0, always defined
    const std::string dot = prefix.empty() ? "" : prefix + ".";
    for (const pb::FieldDescriptor* field : fields) {
        const std::string path = dot + field->name();
        const bool repeated = field->is_repeated();
        const int count = repeated ? reflection.FieldSize(message, field) : 1;
        for (int i = 0; i < count; ++i) {
            const std::string element = repeated ? path + "[" + std::to_string(i) + "]" : path;
            if (field->cpp_type() == pb::FieldDescriptor::CPPTYPE_ENUM) {
                const int value = repeated ? reflection.GetRepeatedEnumValue(message, field, i)
                                           : reflection.GetEnumValue(message, field);
                if (!field->enum_type()->FindValueByNumber(value))
                    return unknown_enum_value(element, *field->enum_type(), value);
            } else if (field->cpp_type() == pb::FieldDescriptor::CPPTYPE_MESSAGE) {
                const pb::Message& child =
                    repeated ? reflection.GetRepeatedMessage(message, field, i) : reflection.GetMessage(message, field);
                if (grpc::Status s = check_enum_values(child, element); !s.ok()) return s;
            }
        }
    }
    return grpc::Status::OK;
}

RenderOptions render_options_for(const v1::PipelineOptions& p, const v1::Color* background) {
    // Unset fields take the defaults every tool shares (default_pipeline_options: the fastest
    // configuration at the accuracy bar, the paper's cache with split k = 8192).
    RenderOptions o = default_pipeline_options();
    switch (p.culling()) {
        case v1::CULLING_EXACT:
            o.culling = Culling::exact;
            break;
        case v1::CULLING_BBOX3SIGMA:
            o.culling = Culling::bbox3sigma;
            break;
        case v1::CULLING_OPACITY_AWARE:
            o.culling = Culling::opacity_aware;
            break;
        default:
            break;
    }
    if (background) o.background = {background->r(), background->g(), background->b()};
    if (p.near_plane() > 0) o.near_plane = p.near_plane();
    CatgsOptions& c = o.catgs;
    switch (p.cache()) {
        case v1::CACHE_MODE_OFF:
            c.cache = CacheMode::off;
            break;
        case v1::CACHE_MODE_SPECULATIVE:
            c.cache = CacheMode::speculative;
            break;
        default:
            break;
    }
    if (p.fixed_window() > 0) {
        c.adaptive_window = false;
        c.window = static_cast<int>(p.fixed_window());
    } else {
        c.adaptive_window = true;
        if (p.window_start() > 0) c.window = static_cast<int>(p.window_start());
    }
    switch (p.window_cost()) {
        case v1::WINDOW_COST_TIME:
            c.window_cost = WindowCost::time;
            break;
        case v1::WINDOW_COST_WORK:
            c.window_cost = WindowCost::work;
            break;
        case v1::WINDOW_COST_OFF:
            c.window_cost = WindowCost::off;
            break;
        default:
            break;
    }
    if (p.has_reuse_depth_order()) c.resort_cached = !p.reuse_depth_order();
    if (p.has_reuse_order_max_degrees()) c.reuse_order_max_angle = p.reuse_order_max_degrees() * kPi / 180.0;
    switch (p.split()) {
        case v1::SPLIT_MODE_OFF:
            c.split_auto = false;
            c.split_k = 0;
            break;
        case v1::SPLIT_MODE_AUTO:
            c.split_auto = true;
            break;
        case v1::SPLIT_MODE_FIXED:
            c.split_auto = false;
            c.split_k = p.split_k();
            break;
        default:
            break;
    }
    return o;
}

grpc::Status parse_session_config(const v1::SessionConfig& config, const Limits& limits, const std::string& prefix,
                                  SessionSetup* out) {
    if (grpc::Status s = check_enum_values(config, prefix); !s.ok()) return s;
    const std::string f = prefix + ".";
    if (config.scene_id().empty()) return invalid(f + "scene_id", "empty");
    for (const auto& [name, value] : {std::pair{"width", config.width()}, std::pair{"height", config.height()}})
        if (value < 1 || value > kMaxProtocolDimension)
            return invalid(f + name, std::to_string(value) + " is outside 1.." + std::to_string(kMaxProtocolDimension));
    const int width = static_cast<int>(config.width()), height = static_cast<int>(config.height());
    if (width > limits.max_width || height > limits.max_height)
        return {grpc::StatusCode::RESOURCE_EXHAUSTED, "max-resolution: " + std::to_string(width) + "x" +
                                                          std::to_string(height) + " exceeds this server's limit of " +
                                                          std::to_string(limits.max_width) + "x" +
                                                          std::to_string(limits.max_height)};

    Intrinsics k;
    if (grpc::Status s = config.has_intrinsics() ? parse_intrinsics(config.intrinsics(), width, height, f, &k)
                                                 : parse_field_of_view(config, width, height, f, &k);
        !s.ok())
        return s;

    EncodeSettings e;
    const auto& enc = config.encoding();
    switch (enc.encoding()) {
        case v1::ENCODING_UNSPECIFIED:
        case v1::ENCODING_JPEG:
            e.format = Format::jpeg;
            break;
        case v1::ENCODING_PNG:
            e.format = Format::png;
            break;
        case v1::ENCODING_RAW_RGB8:
            e.format = Format::raw_rgb8;
            break;
        default:
            return invalid(f + "encoding.encoding",
                           "unknown value " + std::to_string(enc.encoding()));  // not reached: checked above
    }
    if (enc.jpeg_quality() < 0 || enc.jpeg_quality() > 100)
        return invalid(f + "encoding.jpeg_quality",
                       std::to_string(enc.jpeg_quality()) + " is outside 1..100 (0: default)");
    e.jpeg_quality = enc.jpeg_quality() == 0 ? kDefaultJpegQuality : enc.jpeg_quality();
    e.jpeg_444 = enc.jpeg_subsampling() == v1::CHROMA_SUBSAMPLING_444;

    if (config.has_background()) {
        const auto& b = config.background();
        for (float c : {b.r(), b.g(), b.b()})
            if (!(c >= 0.0f && c <= 1.0f)) return invalid(f + "background", "components must be in [0, 1]");
    }
    const auto& p = config.pipeline();
    const std::string pf = f + "pipeline.";
    if (p.fixed_window() > static_cast<std::uint32_t>(kMaxWindow))
        return invalid(pf + "fixed_window", std::to_string(p.fixed_window()) + " is outside 0..16");
    if (p.window_start() > static_cast<std::uint32_t>(kMaxWindow))
        return invalid(pf + "window_start", std::to_string(p.window_start()) + " is outside 0..16");
    if (p.split() == v1::SPLIT_MODE_FIXED && (p.split_k() < 1 || p.split_k() > kMaxSplitK))
        return invalid(pf + "split_k", std::to_string(p.split_k()) + " is outside 1..16777216");
    if (!(std::isfinite(p.near_plane()) && p.near_plane() >= 0))
        return invalid(pf + "near_plane", format_number(p.near_plane()) + " is not a non-negative distance");
    if (p.has_reuse_order_max_degrees() && !(p.reuse_order_max_degrees() >= 0 && p.reuse_order_max_degrees() <= 180))
        return invalid(pf + "reuse_order_max_degrees",
                       format_number(p.reuse_order_max_degrees()) + " is outside 0..180");
    if (grpc::Status s = check_client_name(config.client_name(), f + "client_name"); !s.ok()) return s;
    if (config.max_unacked_frames() > static_cast<std::uint32_t>(kMaxUnackedFramesLimit))
        return invalid(f + "max_unacked_frames", std::to_string(config.max_unacked_frames()) + " is outside 0..2");

    out->scene_id = config.scene_id();
    out->intrinsics = k;
    out->options = render_options_for(p, config.has_background() ? &config.background() : nullptr);
    out->encode = e;
    out->max_unacked_frames =
        config.max_unacked_frames() == 0 ? kDefaultMaxUnackedFrames : static_cast<int>(config.max_unacked_frames());
    return grpc::Status::OK;
}

Camera camera_from_pose(const v1::Pose& pose, const Intrinsics& intrinsics, std::int64_t client_timestamp_us) {
    Camera camera;
    camera.intrinsics = intrinsics;
    camera.pose = wire::from_proto(pose);
    // The planner derives frame intervals from timestamps: use the client's clock, which is
    // what the motion really followed (server receive times add network jitter).
    camera.timestamp = static_cast<double>(client_timestamp_us) * 1e-6;
    return camera;
}

grpc::Status check_flight_plan_length(const v1::FrameRequest& request, const std::string& prefix) {
    if (request.flight_plan_size() > kMaxFlightPlanPoses)
        return invalid(prefix + ".flight_plan", std::to_string(request.flight_plan_size()) + " poses; at most " +
                                                    std::to_string(kMaxFlightPlanPoses) + " are used");
    return grpc::Status::OK;
}

namespace {

grpc::Status check_frame_fields(const v1::FrameRequest& request, const std::string& f) {
    if (!request.has_pose()) return invalid(f + "pose", "missing");
    if (grpc::Status s = check_pose(request.pose(), f + "pose"); !s.ok()) return s;
    if (request.has_linear_velocity() && !finite(request.linear_velocity()))
        return invalid(f + "linear_velocity", "not finite");
    if (request.has_angular_speed() && !(std::isfinite(request.angular_speed()) && request.angular_speed() >= 0))
        return invalid(f + "angular_speed",
                       format_number(request.angular_speed()) + " is not a finite non-negative speed");
    for (int i = 0; i < request.flight_plan_size(); ++i) {
        const std::string pf = f + "flight_plan[" + std::to_string(i) + "].pose";
        if (!request.flight_plan(i).has_pose()) return invalid(pf, "missing");
        if (grpc::Status s = check_pose(request.flight_plan(i).pose(), pf); !s.ok()) return s;
    }
    return grpc::Status::OK;
}

grpc::Status frame_cameras(const v1::FrameRequest& request, const Intrinsics& intrinsics, const std::string& f,
                           FrameSetup* out) {
    if (grpc::Status s =
            checked_camera(request.pose(), intrinsics, request.client_timestamp_us(), f + "pose", &out->camera);
        !s.ok())
        return s;
    out->hints.reset();
    if (!request.has_linear_velocity() && !request.has_angular_speed() && request.flight_plan_size() == 0)
        return grpc::Status::OK;
    FrameHints hints;
    if (request.has_linear_velocity())
        hints.linear_velocity = {request.linear_velocity().x(), request.linear_velocity().y(),
                                 request.linear_velocity().z()};
    if (request.has_angular_speed()) hints.angular_speed = request.angular_speed();
    for (int i = 0; i < request.flight_plan_size(); ++i) {
        const v1::TimedPose& planned = request.flight_plan(i);
        const std::string pf = f + "flight_plan[" + std::to_string(i) + "].pose";
        if (grpc::Status s = checked_camera(planned.pose(), intrinsics, planned.client_timestamp_us(), pf,
                                            &hints.plan.emplace_back());
            !s.ok())
            return s;
    }
    out->hints = std::move(hints);
    return grpc::Status::OK;
}

}  // namespace

grpc::Status parse_frame_request(const v1::FrameRequest& request, const Intrinsics& intrinsics,
                                 const std::string& prefix, FrameSetup* out) {
    // Before the walk over every element, which a 1 MiB plan of empty poses makes costly.
    if (grpc::Status s = check_flight_plan_length(request, prefix); !s.ok()) return s;
    if (grpc::Status s = check_enum_values(request, prefix); !s.ok()) return s;
    const std::string f = prefix + ".";
    if (grpc::Status s = check_frame_fields(request, f); !s.ok()) return s;
    out->sequence = request.sequence();
    out->client_timestamp_us = request.client_timestamp_us();
    out->last_received_sequence = request.last_received_sequence();
    try {
        return frame_cameras(request, intrinsics, f, out);
    } catch (const Error& e) {
        return invalid(f + "pose", e.what());
    }
}

v1::Encoding to_proto(Format format) {
    switch (format) {
        case Format::jpeg:
            return v1::ENCODING_JPEG;
        case Format::png:
            return v1::ENCODING_PNG;
        case Format::raw_rgb8:
            return v1::ENCODING_RAW_RGB8;
    }
    return v1::ENCODING_UNSPECIFIED;
}

}  // namespace catgs::server
