// How a finished RPC becomes catgs-client's exit status and its one line on stderr. The
// numbers are catgs/common/exit_codes.hpp.
#pragma once

#include <grpcpp/grpcpp.h>

#include <string>

namespace catgs::client {

/// kExitOk for OK, else the status code's class (unavailable, limit, unauthenticated,
/// rejected), else kExitFailure.
int exit_code(const grpc::Status& status);

/// "INVALID_ARGUMENT", ...; "?" outside the known codes.
const char* code_name(grpc::StatusCode code);

/// Prints "catgs-client: WHAT: CODE: message" to stderr and returns exit_code(status).
int report_failure(const std::string& what, const grpc::Status& status);

}  // namespace catgs::client
