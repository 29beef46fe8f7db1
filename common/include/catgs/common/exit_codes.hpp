// The exit statuses of every catgs executable, in one table so that scripts (deploy/demo.sh,
// CI) can rely on a number meaning the same thing whichever tool returned it. catgs-render,
// catgs-bench and catgs-server use the first three; catgs-client maps gRPC status codes onto
// the rest (client/src/exit_status.cpp).
#pragma once

namespace catgs {

inline constexpr int kExitOk = 0;
/// Anything not covered below (an I/O error, a failed render, an RPC failed otherwise).
inline constexpr int kExitFailure = 1;
/// Bad flags or input; one line on stderr names the problem.
inline constexpr int kExitBadInput = 2;
/// The server is unreachable or shutting down (UNAVAILABLE after the retries, DEADLINE_EXCEEDED).
inline constexpr int kExitUnavailable = 3;
/// Refused by a server limit (RESOURCE_EXHAUSTED).
inline constexpr int kExitLimit = 4;
/// Not authenticated (UNAUTHENTICATED, PERMISSION_DENIED).
inline constexpr int kExitUnauthenticated = 5;
/// The server rejected the request (INVALID_ARGUMENT, NOT_FOUND, FAILED_PRECONDITION, ALREADY_EXISTS).
inline constexpr int kExitRejected = 6;

}  // namespace catgs
