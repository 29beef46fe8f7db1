#include "exit_status.hpp"

#include <iostream>

#include "catgs/common/exit_codes.hpp"

namespace catgs::client {

int exit_code(const grpc::Status& s) {
    switch (s.error_code()) {
        case grpc::StatusCode::OK:
            return kExitOk;
        case grpc::StatusCode::UNAVAILABLE:
        case grpc::StatusCode::DEADLINE_EXCEEDED:
            return kExitUnavailable;
        case grpc::StatusCode::RESOURCE_EXHAUSTED:
            return kExitLimit;
        case grpc::StatusCode::UNAUTHENTICATED:
        case grpc::StatusCode::PERMISSION_DENIED:
            return kExitUnauthenticated;
        case grpc::StatusCode::INVALID_ARGUMENT:
        case grpc::StatusCode::NOT_FOUND:
        case grpc::StatusCode::FAILED_PRECONDITION:
        case grpc::StatusCode::ALREADY_EXISTS:
            return kExitRejected;
        default:
            return kExitFailure;
    }
}

const char* code_name(grpc::StatusCode code) {
    static const char* names[] = {
        "OK",        "CANCELLED",      "UNKNOWN",           "INVALID_ARGUMENT",   "DEADLINE_EXCEEDED",
        "NOT_FOUND", "ALREADY_EXISTS", "PERMISSION_DENIED", "RESOURCE_EXHAUSTED", "FAILED_PRECONDITION",
        "ABORTED",   "OUT_OF_RANGE",   "UNIMPLEMENTED",     "INTERNAL",           "UNAVAILABLE",
        "DATA_LOSS", "UNAUTHENTICATED"};
    const int i = static_cast<int>(code);
    return i >= 0 && i < 17 ? names[i] : "?";
}

int report_failure(const std::string& what, const grpc::Status& status) {
    std::cerr << "catgs-client: " << what << ": " << code_name(status.error_code()) << ": " << status.error_message()
              << "\n";
    return exit_code(status);
}

}  // namespace catgs::client
