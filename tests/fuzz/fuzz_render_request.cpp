// libFuzzer target: a RenderService.Render request from bytes. The bytes are parsed as a
// catgs.v1.RenderRequest (protobuf wire format, as gRPC hands it to the service), then the
// server's validation runs on it as RenderServiceImpl::Render does: the opening message
// (parse_session_config, prefix "config") and, when that passes, the frame request
// (parse_frame_request against the session's intrinsics, prefix "frame").

#include <cstddef>
#include <cstdint>

#include "catgs/server/request_validation.hpp"
#include "catgs/v1/catgs.pb.h"
#include "fuzz_util.hpp"
#include "request_checks.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    if (size > catgs::fuzz::kMaxInputBytes) return -1;
    catgs::v1::RenderRequest request;
    if (!request.ParseFromArray(data, static_cast<int>(size))) return -1;
    static const catgs::server::Limits limits;  // the server's defaults (3840x2160)
    catgs::server::SessionSetup setup;
    const grpc::Status config = catgs::server::parse_session_config(request.config(), limits, "config", &setup);
    if (!config.ok()) {
        catgs::fuzz::check_refusal(config, "config");
        return 0;
    }
    catgs::fuzz::check_session(setup, limits);
    catgs::server::FrameSetup frame;
    const grpc::Status status = catgs::server::parse_frame_request(request.frame(), setup.intrinsics, "frame", &frame);
    if (!status.ok()) {
        catgs::fuzz::check_refusal(status, "frame");
        return 0;
    }
    catgs::fuzz::check_frame(frame);
    return 0;
}
