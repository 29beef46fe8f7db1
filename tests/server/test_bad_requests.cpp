// Bad requests: every one gets the right status code and a message naming the field, and a
// healthy stream on the same server keeps receiving frames meanwhile.
#include <google/protobuf/descriptor.h>
#include <google/protobuf/message.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "server_test_util.hpp"

namespace catgs::test {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

class BadRequestTest : public HealthyStreamTest<BadRequestTest> {
public:
    static server::ServerOptions options() {
        server::ServerOptions o = test_options();
        o.limits.max_width = 1920;
        o.limits.max_height = 1080;
        return o;
    }

protected:
    /// Opens a stream with `config` and expects it to fail with `code` and `message` in its text.
    static void expect_open_fails(const v1::SessionConfig& config, grpc::StatusCode code, const std::string& message) {
        StreamClient client(channel_to(server_->port()));
        client.open(config);
        client.send(frame_request(1, uav_path(2)[0], 0));
        const grpc::Status status = client.close();
        EXPECT_EQ(status.error_code(), code) << status.error_message();
        EXPECT_NE(status.error_message().find(message), std::string::npos)
            << "'" << status.error_message() << "' does not contain '" << message << "'";
    }

    /// A unary Render of `request` fails with INVALID_ARGUMENT and `message` in its text.
    static void expect_render_fails(const v1::RenderRequest& request, const std::string& message) {
        v1::Frame frame;
        const grpc::Status status = render_once(channel_to(server_->port()), request, &frame);
        EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << status.error_message();
        EXPECT_NE(status.error_message().find(message), std::string::npos)
            << "'" << status.error_message() << "' does not contain '" << message << "'";
    }
};

/// Far out along x and z and turned 45 degrees about y: the camera's translation, a sum of
/// both coordinates, overflows a double.
void set_overflowing_pose(v1::Pose* pose) {
    pose->mutable_position()->set_x(-1.3e308);
    pose->mutable_position()->set_y(0);
    pose->mutable_position()->set_z(-1.3e308);
    auto* q = pose->mutable_orientation();
    q->set_w(0.92388), q->set_x(0), q->set_y(0.38268), q->set_z(0);
}

TEST_F(BadRequestTest, StreamWithoutOpeningMessage) {
    StreamClient client(channel_to(server_->port()));
    ASSERT_TRUE(client.send(frame_request(1, uav_path(2)[0], 0)));
    const grpc::Status status = client.close();
    EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_NE(status.error_message().find("open: the first message of a stream must be StreamRequest.open"),
              std::string::npos)
        << status.error_message();
}

TEST_F(BadRequestTest, StreamClosedBeforeOpening) {
    StreamClient client(channel_to(server_->port()));
    const grpc::Status status = client.close();
    EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_NE(status.error_message().find("open: the stream ended before its opening message"), std::string::npos)
        << status.error_message();
}

TEST_F(BadRequestTest, ZeroAndHugeResolution) {
    v1::SessionConfig config = session_config(v1::ENCODING_JPEG);
    config.set_width(0);
    expect_open_fails(config, grpc::StatusCode::INVALID_ARGUMENT, "open.width: 0 is outside 1..16384");
    config = session_config(v1::ENCODING_JPEG);
    config.set_height(1'000'000);
    expect_open_fails(config, grpc::StatusCode::INVALID_ARGUMENT, "open.height: 1000000 is outside 1..16384");
}

TEST_F(BadRequestTest, ResolutionAboveTheServerLimitIsResourceExhausted) {
    v1::SessionConfig config = session_config(v1::ENCODING_JPEG);
    config.set_width(3840);
    config.set_height(2160);
    expect_open_fails(config, grpc::StatusCode::RESOURCE_EXHAUSTED,
                      "max-resolution: 3840x2160 exceeds this server's limit of 1920x1080");
}

TEST_F(BadRequestTest, UnknownScene) {
    expect_open_fails(session_config(v1::ENCODING_JPEG, 0, "atlantis"), grpc::StatusCode::INVALID_ARGUMENT,
                      "open.scene_id 'atlantis': no such scene");
    expect_open_fails(session_config(v1::ENCODING_JPEG, 0, ""), grpc::StatusCode::INVALID_ARGUMENT,
                      "open.scene_id: empty");
    // The message reaches the server's log: a newline in the id must not start a line there.
    expect_open_fails(session_config(v1::ENCODING_JPEG, 0, "x\n[info] forged"), grpc::StatusCode::INVALID_ARGUMENT,
                      "open.scene_id 'x\\x0a[info] forged': no such scene");
    expect_open_fails(session_config(v1::ENCODING_JPEG, 0, std::string(200, 'a')), grpc::StatusCode::INVALID_ARGUMENT,
                      "open.scene_id '" + std::string(128, 'a') + "...': no such scene");
}

TEST_F(BadRequestTest, IntrinsicsThatDisagreeWithTheResolution) {
    v1::SessionConfig config = session_config(v1::ENCODING_JPEG);
    auto* k = config.mutable_intrinsics();
    k->set_fx(100);
    k->set_fy(100);
    k->set_cx(kWidth + 5);  // principal point right of the image
    k->set_cy(kHeight / 2.0);
    expect_open_fails(config, grpc::StatusCode::INVALID_ARGUMENT,
                      "open.intrinsics.cx: principal point 165 is outside the image width 0..160");
    k->set_cx(kWidth / 2.0);
    k->set_cy(-1);
    expect_open_fails(config, grpc::StatusCode::INVALID_ARGUMENT,
                      "open.intrinsics.cy: principal point -1 is outside the image height 0..90");
    k->set_cy(kHeight / 2.0);
    k->set_fx(0);
    expect_open_fails(config, grpc::StatusCode::INVALID_ARGUMENT,
                      "open.intrinsics.fx: 0 is not a positive focal length");
    k->set_fx(100);
    k->set_fy(kNaN);
    expect_open_fails(config, grpc::StatusCode::INVALID_ARGUMENT,
                      "open.intrinsics.fy: nan is not a positive focal length");
}

/// Focal lengths a double holds but a float does not (the renderers' type) drew blank frames.
TEST_F(BadRequestTest, FocalLengthsOutsideASaneFieldOfView) {
    v1::SessionConfig config = session_config(v1::ENCODING_JPEG);
    auto* k = config.mutable_intrinsics();
    k->set_cx(kWidth / 2.0);
    k->set_cy(kHeight / 2.0);
    k->set_fx(1e300);
    k->set_fy(1e300);
    expect_open_fails(config, grpc::StatusCode::INVALID_ARGUMENT,
                      "open.intrinsics.fx: 1e+300 gives a horizontal field of view of 9.16732e-297 degrees, "
                      "outside [0.001, 179.9]");
    expect_render_fails(render_request(config, frame_request(1, uav_path(2)[0], 0)),
                        "config.intrinsics.fx: 1e+300 gives a horizontal field of view of");
    k->set_fx(1e-300);
    expect_open_fails(config, grpc::StatusCode::INVALID_ARGUMENT,
                      "open.intrinsics.fx: 1e-300 gives a horizontal field of view of 180 degrees, "
                      "outside [0.001, 179.9]");
    k->set_fx(100);
    expect_open_fails(config, grpc::StatusCode::INVALID_ARGUMENT,
                      "open.intrinsics.fy: 1e+300 gives a vertical field of view of 5.15662e-297 degrees, "
                      "outside [0.001, 179.9]");
    k->set_fy(0.01);  // 0.01 pixels over 90 rows: 179.97 degrees
    expect_open_fails(config, grpc::StatusCode::INVALID_ARGUMENT,
                      "open.intrinsics.fy: 0.01 gives a vertical field of view of 179.975 degrees, "
                      "outside [0.001, 179.9]");
    config = session_config(v1::ENCODING_JPEG);
    config.set_horizontal_fov_degrees(1e-100);
    expect_open_fails(config, grpc::StatusCode::INVALID_ARGUMENT,
                      "open.horizontal_fov_degrees: 1e-100 is outside [0.001, 179.9]");
    config.set_horizontal_fov_degrees(179.95);
    expect_open_fails(config, grpc::StatusCode::INVALID_ARGUMENT,
                      "open.horizontal_fov_degrees: 179.95 is outside [0.001, 179.9]");
    // The ends of the range render.
    for (double fov : {kMinFieldOfViewDegrees, kMaxFieldOfViewDegrees}) {
        config.set_horizontal_fov_degrees(fov);
        expect_one_frame(channel_to(server_->port()), config);
    }
}

TEST_F(BadRequestTest, BadEncodingAndPipelineOptions) {
    v1::SessionConfig config = session_config(v1::ENCODING_JPEG, 101);
    expect_open_fails(config, grpc::StatusCode::INVALID_ARGUMENT, "open.encoding.jpeg_quality: 101 is outside 1..100");
    config = session_config(v1::ENCODING_JPEG);
    config.mutable_pipeline()->set_fixed_window(17);
    expect_open_fails(config, grpc::StatusCode::INVALID_ARGUMENT, "open.pipeline.fixed_window: 17 is outside 0..16");
    config = session_config(v1::ENCODING_JPEG);
    config.mutable_pipeline()->set_reuse_order_max_degrees(-0.5);
    expect_open_fails(config, grpc::StatusCode::INVALID_ARGUMENT,
                      "open.pipeline.reuse_order_max_degrees: -0.5 is outside 0..180");
    config.mutable_pipeline()->set_reuse_order_max_degrees(kNaN);
    expect_open_fails(config, grpc::StatusCode::INVALID_ARGUMENT,
                      "open.pipeline.reuse_order_max_degrees: nan is outside 0..180");
    config = session_config(v1::ENCODING_JPEG);
    config.set_max_unacked_frames(5);
    expect_open_fails(config, grpc::StatusCode::INVALID_ARGUMENT, "open.max_unacked_frames: 5 is outside 0..2");
}

/// Bad frame requests get an error frame each, and the session goes on rendering good ones.
TEST_F(BadRequestTest, BadFrameRequestsAnswerThatFrameAndKeepTheSession) {
    const auto path = uav_path(4);
    StreamClient client(channel_to(server_->port()));
    ASSERT_TRUE(client.open(session_config(v1::ENCODING_JPEG)));
    struct Case {
        const char* name;
        std::function<void(v1::FrameRequest&)> spoil;
        std::string message;
    };
    const std::vector<Case> cases = {
        {"NaN position", [](v1::FrameRequest& r) { r.mutable_pose()->mutable_position()->set_y(kNaN); },
         "frame.pose.position: not finite"},
        {"infinite quaternion", [](v1::FrameRequest& r) { r.mutable_pose()->mutable_orientation()->set_w(kInf); },
         "frame.pose.orientation: quaternion is not finite"},
        {"zero quaternion",
         [](v1::FrameRequest& r) {
             auto* q = r.mutable_pose()->mutable_orientation();
             q->set_w(0), q->set_x(0), q->set_y(0), q->set_z(0);
         },
         "frame.pose.orientation: quaternion has zero length"},
        {"missing pose", [](v1::FrameRequest& r) { r.clear_pose(); }, "frame.pose: missing"},
        {"NaN velocity", [](v1::FrameRequest& r) { r.mutable_linear_velocity()->set_x(kNaN); },
         "frame.linear_velocity: not finite"},
        {"NaN flight plan",
         [](v1::FrameRequest& r) {
             auto* p = r.add_flight_plan();
             *p->mutable_pose() = r.pose();
             p->mutable_pose()->mutable_position()->set_z(kNaN);
         },
         "frame.flight_plan[0].pose.position: not finite"},
        {"overflowing position", [](v1::FrameRequest& r) { set_overflowing_pose(r.mutable_pose()); },
         "frame.pose.position.x: -1.3e+308 is beyond +-1e30"},
        {"far flight plan",
         [](v1::FrameRequest& r) {
             auto* p = r.add_flight_plan();
             *p->mutable_pose() = r.pose();
             p->mutable_pose()->mutable_position()->set_z(2e30);
         },
         "frame.flight_plan[0].pose.position.z: 2e+30 is beyond +-1e30"},
    };
    std::uint64_t seq = 0, ack = 0;
    for (const Case& c : cases) {
        SCOPED_TRACE(c.name);
        ++seq;
        v1::FrameRequest bad = frame_request(seq, path[seq % 4], ack);
        c.spoil(bad);
        ASSERT_TRUE(client.send(bad));
        v1::Frame frame;
        ASSERT_TRUE(client.stream->Read(&frame));
        EXPECT_EQ(frame.sequence(), seq);
        ASSERT_TRUE(frame.has_error());
        EXPECT_EQ(frame.error().code(), static_cast<int>(grpc::StatusCode::INVALID_ARGUMENT));
        EXPECT_NE(frame.error().message().find(c.message), std::string::npos) << frame.error().message();
        EXPECT_TRUE(frame.data().empty());
        // The next good request still renders.
        ++seq;
        ASSERT_TRUE(client.send(frame_request(seq, path[seq % 4], ack)));
        ASSERT_TRUE(client.stream->Read(&frame));
        EXPECT_FALSE(frame.has_error()) << frame.error().message();
        EXPECT_EQ(frame.sequence(), seq);
        EXPECT_FALSE(frame.data().empty());
        ack = frame.sequence();
    }
    // A repeated sequence number is refused too.
    ASSERT_TRUE(client.send(frame_request(seq, path[0], ack)));
    v1::Frame frame;
    ASSERT_TRUE(client.stream->Read(&frame));
    ASSERT_TRUE(frame.has_error());
    EXPECT_NE(
        frame.error().message().find("frame.sequence: " + std::to_string(seq) + " is not greater than the previous"),
        std::string::npos)
        << frame.error().message();
    EXPECT_EQ(frame.stats().frame_errors(), cases.size() + 1);
    EXPECT_TRUE(client.close().ok());
}

namespace pb = google::protobuf;

/// One enum field reachable from a message type: the fields leading to it, and its path as
/// the server names it ("pipeline.cache", "scenes[0].state").
struct EnumField {
    std::vector<const pb::FieldDescriptor*> chain;
    std::string path;
    int unknown_value = 0;  // a number its enum does not define
};

/// Every enum field of `type`, at any depth, found through the descriptors: a field added to
/// the protocol later is in this list without a change to the tests.
void find_enum_fields(const pb::Descriptor* type, EnumField prefix, std::vector<EnumField>* out, int depth = 0) {
    if (depth > 8) return;  // recursive message types
    for (int i = 0; i < type->field_count(); ++i) {
        const pb::FieldDescriptor* field = type->field(i);
        EnumField f = prefix;
        f.chain.push_back(field);
        f.path += (f.path.empty() ? "" : ".") + field->name() + (field->is_repeated() ? "[0]" : "");
        if (field->cpp_type() == pb::FieldDescriptor::CPPTYPE_ENUM) {
            const pb::EnumDescriptor* e = field->enum_type();
            int largest = 0;
            for (int v = 0; v < e->value_count(); ++v) largest = std::max(largest, e->value(v)->number());
            f.unknown_value = largest + 1000;
            out->push_back(f);
        } else if (field->cpp_type() == pb::FieldDescriptor::CPPTYPE_MESSAGE) {
            find_enum_fields(field->message_type(), f, out, depth + 1);
        }
    }
}

std::vector<EnumField> enum_fields(const pb::Descriptor* type) {
    std::vector<EnumField> out;
    find_enum_fields(type, {}, &out);
    return out;
}

/// Sets `field` in `message` to its unknown value (proto3 enums are open: the number is kept).
void spoil(pb::Message& message, const EnumField& field) {
    pb::Message* m = &message;
    for (std::size_t i = 0; i + 1 < field.chain.size(); ++i) {
        const pb::FieldDescriptor* f = field.chain[i];
        const pb::Reflection* r = m->GetReflection();
        m = f->is_repeated() ? (r->FieldSize(*m, f) ? r->MutableRepeatedMessage(m, f, 0) : r->AddMessage(m, f))
                             : r->MutableMessage(m, f);
    }
    const pb::FieldDescriptor* f = field.chain.back();
    if (f->is_repeated())
        m->GetReflection()->AddEnumValue(m, f, field.unknown_value);
    else
        m->GetReflection()->SetEnumValue(m, f, field.unknown_value);
}

std::string unknown_value_message(const std::string& path, const EnumField& field) {
    return path + ": unknown value " + std::to_string(field.unknown_value) + " of " +
           field.chain.back()->enum_type()->full_name() + " (known: ";
}

/// The mechanism itself, on every request type and a response with a repeated message of
/// enums: the first unknown value found is named with its full path.
TEST(EnumValues, EveryEnumFieldOfEveryRequestIsChecked) {
    const std::vector<const pb::Descriptor*> requests = {
        v1::StreamRequest::descriptor(),      v1::RenderRequest::descriptor(),      v1::LoadSceneRequest::descriptor(),
        v1::ListScenesRequest::descriptor(),  v1::UnloadSceneRequest::descriptor(), v1::GetSceneRequest::descriptor(),
        v1::ListScenesResponse::descriptor(),
    };
    int checked = 0;
    for (const pb::Descriptor* type : requests) {
        std::unique_ptr<pb::Message> valid(pb::MessageFactory::generated_factory()->GetPrototype(type)->New());
        EXPECT_TRUE(server::check_enum_values(*valid, "").ok()) << type->full_name();
        for (const EnumField& field : enum_fields(type)) {
            SCOPED_TRACE(type->full_name() + " " + field.path);
            std::unique_ptr<pb::Message> bad(valid->New());
            spoil(*bad, field);
            const grpc::Status status = server::check_enum_values(*bad, "");
            EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
            EXPECT_EQ(status.error_message().rfind(unknown_value_message(field.path, field), 0), 0u)
                << status.error_message();
            ++checked;
        }
    }
    // Today: open/config encoding, jpeg_subsampling, cache, split, culling; scenes[0].state.
    EXPECT_GE(checked, 11);
    const std::vector<EnumField> config_fields = enum_fields(v1::SessionConfig::descriptor());
    std::vector<std::string> paths;
    for (const EnumField& f : config_fields) paths.push_back(f.path);
    for (const char* expected :
         {"encoding.encoding", "encoding.jpeg_subsampling", "pipeline.cache", "pipeline.culling", "pipeline.split"})
        EXPECT_NE(std::find(paths.begin(), paths.end(), expected), paths.end()) << expected;
    // Known values pass, whatever the field.
    v1::SessionConfig known = session_config(v1::ENCODING_PNG);
    known.mutable_pipeline()->set_cache(v1::CACHE_MODE_OFF);
    known.mutable_encoding()->set_jpeg_subsampling(v1::CHROMA_SUBSAMPLING_444);
    EXPECT_TRUE(server::check_enum_values(known, "open").ok());
}

/// Through the server: an unknown value in any enum of the opening message ends the stream,
/// in a unary render's config fails the call, each naming the field and the value.
TEST_F(BadRequestTest, UnknownEnumValuesAreRefusedByEveryMethod) {
    for (const EnumField& field : enum_fields(v1::SessionConfig::descriptor())) {
        SCOPED_TRACE(field.path);
        v1::SessionConfig config = session_config(v1::ENCODING_JPEG);
        spoil(config, field);
        expect_open_fails(config, grpc::StatusCode::INVALID_ARGUMENT,
                          unknown_value_message("open." + field.path, field));
        v1::Frame frame;
        const grpc::Status status = render_once(channel_to(server_->port()),
                                                render_request(config, frame_request(1, uav_path(2)[0], 0)), &frame);
        EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
        EXPECT_NE(status.error_message().find(unknown_value_message("config." + field.path, field)), std::string::npos)
            << status.error_message();
    }
    // The value that was already refused keeps its message.
    v1::SessionConfig config = session_config(v1::ENCODING_JPEG);
    config.mutable_encoding()->set_encoding(static_cast<v1::Encoding>(99));
    expect_open_fails(config, grpc::StatusCode::INVALID_ARGUMENT, "open.encoding.encoding: unknown value 99");
}

/// An unknown enum value in a frame request is an error frame for that request; the session
/// goes on. FrameRequest has no enum field today, so this runs over whatever it gains later.
TEST_F(BadRequestTest, UnknownEnumValuesInAFrameRequestAnswerThatFrame) {
    const auto path = uav_path(3);
    StreamClient client(channel_to(server_->port()));
    ASSERT_TRUE(client.open(session_config(v1::ENCODING_JPEG)));
    std::uint64_t seq = 0;
    for (const EnumField& field : enum_fields(v1::FrameRequest::descriptor())) {
        SCOPED_TRACE(field.path);
        ++seq;
        v1::FrameRequest bad = frame_request(seq, path[0], seq - 1);
        spoil(bad, field);
        ASSERT_TRUE(client.send(bad));
        v1::Frame frame;
        ASSERT_TRUE(client.stream->Read(&frame));
        ASSERT_TRUE(frame.has_error());
        EXPECT_NE(frame.error().message().find(unknown_value_message("frame." + field.path, field)), std::string::npos)
            << frame.error().message();
    }
    ++seq;
    ASSERT_TRUE(client.send(frame_request(seq, path[1], seq - 1)));
    v1::Frame frame;
    ASSERT_TRUE(client.stream->Read(&frame));
    EXPECT_FALSE(frame.has_error()) << frame.error().message();
    EXPECT_TRUE(client.close().ok());
}

TEST_F(BadRequestTest, UnaryRenderValidatesToo) {
    const v1::RenderRequest good =
        render_request(session_config(v1::ENCODING_PNG), frame_request(1, uav_path(2)[0], 0));
    v1::RenderRequest request = good;
    request.mutable_frame()->mutable_pose()->mutable_position()->set_x(kInf);
    expect_render_fails(request, "frame.pose.position: not finite");
    request = good;
    set_overflowing_pose(request.mutable_frame()->mutable_pose());
    expect_render_fails(request, "frame.pose.position.x: -1.3e+308 is beyond +-1e30");
    request = good;
    set_overflowing_pose(request.mutable_frame()->add_flight_plan()->mutable_pose());
    expect_render_fails(request, "frame.flight_plan[0].pose.position.x: -1.3e+308 is beyond +-1e30");
}

/// A plan of empty poses fills a 1 MiB message with 500k elements: its length is refused
/// before the enum walk visits each one, so that error comes first even where an enum value
/// elsewhere in the request is bad too.
TEST_F(BadRequestTest, LongFlightPlansAreRefusedBeforeTheirElementsAreWalked) {
    v1::FrameRequest long_plan = frame_request(1, uav_path(2)[0], 0);
    constexpr int kPoses = 500'000;
    long_plan.mutable_flight_plan()->Reserve(kPoses);
    for (int i = 0; i < kPoses; ++i) long_plan.add_flight_plan();
    const std::string message = "frame.flight_plan: 500000 poses; at most 16 are used";

    v1::RenderRequest request = render_request(session_config(v1::ENCODING_PNG), long_plan);
    request.mutable_config()->mutable_pipeline()->set_cache(static_cast<v1::CacheMode>(99));
    expect_render_fails(request, message);

    StreamClient client(channel_to(server_->port()));
    ASSERT_TRUE(client.open(session_config(v1::ENCODING_JPEG)));
    ASSERT_TRUE(client.send(long_plan));
    v1::Frame frame;
    ASSERT_TRUE(client.stream->Read(&frame));
    ASSERT_TRUE(frame.has_error());
    EXPECT_EQ(frame.error().code(), static_cast<int>(grpc::StatusCode::INVALID_ARGUMENT));
    EXPECT_NE(frame.error().message().find(message), std::string::npos) << frame.error().message();
    ASSERT_TRUE(client.send(frame_request(2, uav_path(2)[1], 0)));
    ASSERT_TRUE(client.stream->Read(&frame));
    EXPECT_FALSE(frame.has_error()) << frame.error().message();
    EXPECT_TRUE(client.close().ok());
}

/// The server's log lines quote client_name: a newline in it would forge a line, an escape
/// sequence hide one.
TEST_F(BadRequestTest, ClientNamesWithControlCharacters) {
    v1::SessionConfig config = session_config(v1::ENCODING_JPEG);
    config.set_client_name("viewer 1.2\n2024-01-01 [info] session 7 opened by admin");
    expect_open_fails(config, grpc::StatusCode::INVALID_ARGUMENT,
                      "open.client_name: control character 0x0a at byte 10; only printable text is accepted");
    expect_render_fails(render_request(config, frame_request(1, uav_path(2)[0], 0)),
                        "config.client_name: control character 0x0a at byte 10");
    config.set_client_name("\x1b[2Kviewer");
    expect_open_fails(config, grpc::StatusCode::INVALID_ARGUMENT, "open.client_name: control character 0x1b at byte 0");
    config.set_client_name(std::string("viewer") + '\x7f');
    expect_open_fails(config, grpc::StatusCode::INVALID_ARGUMENT, "open.client_name: control character 0x7f at byte 6");
    config.set_client_name("caméra 3 (étage 2)");  // UTF-8 is text
    expect_one_frame(channel_to(server_->port()), config);
}

}  // namespace
}  // namespace catgs::test
