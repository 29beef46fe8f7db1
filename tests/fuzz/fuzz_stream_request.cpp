// libFuzzer target: a client message of RenderService.Stream from bytes, parsed as a
// catgs.v1.StreamRequest and validated as StreamSession does: `open` by parse_session_config
// (prefix "open"), `frame` by parse_frame_request (prefix "frame") against the intrinsics of
// a session opened with the defaults (1280x720, 70 degrees).

#include <cstddef>
#include <cstdint>

#include "catgs/camera.hpp"
#include "catgs/server/request_validation.hpp"
#include "catgs/v1/catgs.pb.h"
#include "fuzz_util.hpp"
#include "request_checks.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    if (size > catgs::fuzz::kMaxInputBytes) return -1;
    catgs::v1::StreamRequest request;
    if (!request.ParseFromArray(data, static_cast<int>(size))) return -1;
    static const catgs::server::Limits limits;
    static const catgs::Intrinsics session = catgs::intrinsics_from_fov(1280, 720, 70.0);
    if (request.has_open()) {
        catgs::server::SessionSetup setup;
        const grpc::Status status = catgs::server::parse_session_config(request.open(), limits, "open", &setup);
        if (status.ok())
            catgs::fuzz::check_session(setup, limits);
        else
            catgs::fuzz::check_refusal(status, "open");
    } else if (request.has_frame()) {
        catgs::server::FrameSetup frame;
        const grpc::Status status = catgs::server::parse_frame_request(request.frame(), session, "frame", &frame);
        if (status.ok())
            catgs::fuzz::check_frame(frame);
        else
            catgs::fuzz::check_refusal(status, "frame");
    }
    return 0;
}
